"""Scenarios over real processes, and what the terminal shows while one runs.

:func:`run_over_bus` runs a scenario the way a robot runs: the lower computer is
``lowerbase emulate`` in a child process on the default transport (udp_multicast, hop limit 0,
a free port of its own so parallel runs never meet), and the upper side is a
:class:`DriverCore` on a python-can bus in this process, in real time. Faults are handed to
the emulator as ``--fault SPEC@T+D`` (times from its boot, which is the scenario's t = 0: the
first Heartbeat's Uptime aligns the clocks); the ground truth comes back through
``emulate --truth FILE``. The child runs in its own session, so Ctrl-C reaches only us; it is
stopped (SIGINT, then SIGKILL after a grace period) on every way out, and bounded by
``--duration`` in case this process dies without cleaning up.

:class:`ProgressBar` and :class:`StatusLine` write one line to stderr, refreshed in place on a
terminal.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from lowerbase.clock import Clock
from lowerbase.errors import ConfigError, TransportError
from lowerbase.scenarios.lag import HostLag
from lowerbase.scenarios.runner import FrameTap, Harness, RunResult, run_scenario
from lowerbase.scenarios.timeline import ROBOT_STATES, Action, FaultAt, Unplug
from lowerbase.scenarios.wheeled import Scenario
from lowerbase.transport import free_loopback_port, is_catalog_frame

READY_TEXT = "lower computer on"
START_TIMEOUT = 20.0  #: [s] for the emulator to start listening and send a Heartbeat
STOP_GRACE = 5.0  #: [s] after SIGINT before the emulator is killed


def default_bus_config(port: int | None = None) -> dict[str, Any]:
    """The default transport (udp_multicast, this host only) on a port of its own."""
    from lowerbase.transport import DEFAULT_CHANNEL, DEFAULT_HOP_LIMIT

    return {"interface": "udp_multicast", "channel": DEFAULT_CHANNEL,
            "port": port or free_loopback_port(), "hop_limit": DEFAULT_HOP_LIMIT}


def describe_bus(config: dict[str, Any]) -> str:
    """``udp_multicast 239.74.163.2 port 50000`` and the like."""
    extra = ", ".join(f"{k} {v}" for k, v in config.items() if k not in ("interface", "channel"))
    return f"{config['interface']} {config['channel']}" + (f" ({extra})" if extra else "")


def bus_flags(config: dict[str, Any]) -> list[str]:
    """``config`` as python-can command-line flags."""
    extra = [f"{k}={v}" for k, v in config.items() if k not in ("interface", "channel")]
    return ["-i", str(config["interface"]), "-c", str(config["channel"]),
            *(["--bus-kwargs", *extra] if extra else [])]


def check_over_bus(scenario: Scenario) -> None:
    """ConfigError when the scenario needs the lower computer in this process."""
    needs = scenario.in_process_only()
    if needs:
        raise ConfigError(f"{scenario.source}: cannot run over processes: it needs "
                          f"{', '.join(needs)} (run it without --processes)")
    reboot = any(getattr(a, "command", "") == "Reboot" for a in scenario.timeline)
    if reboot and scenario.faults:
        raise ConfigError(f"{scenario.source}: cannot run over processes: the emulator counts "
                          "fault times from its latest boot, and this scenario reboots it")


class EmulatorProcess:
    """``lowerbase emulate`` as a child process; output goes to ``log_path``."""

    def __init__(self, args: list[str], log_path: Path) -> None:
        self.log_path = log_path
        self._log = log_path.open("w", encoding="utf-8")
        self.popen = subprocess.Popen(
            [sys.executable, "-m", "lowerbase", "emulate", *args],
            stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True,  # our Ctrl-C is ours to handle; we stop the child
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )

    def output(self) -> str:
        try:
            return self.log_path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return ""

    def wait_ready(self, timeout: float = START_TIMEOUT) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if READY_TEXT in self.output():
                return
            if self.popen.poll() is not None:
                break
            time.sleep(0.05)
        self.stop()
        lines = [ln for ln in self.output().splitlines() if ln.strip()]
        why = lines[-1] if lines else "no output"
        raise TransportError(f"the emulator did not start ({why}); log: {self.log_path}; "
                             "`lowerbase demo --fast` runs without a bus")

    def stop(self) -> int | None:
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                self.popen.send_signal(signal.SIGINT)
            try:
                self.popen.wait(STOP_GRACE)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(STOP_GRACE)
        self._log.close()
        return self.popen.returncode


class BusHarness:
    """DriverCore on a python-can bus, real time; the lower computer is elsewhere."""

    def __init__(self, bus: Any, *, truth_path: Path | None = None,
                 tap: FrameTap | None = None, dt: float = 0.005,
                 clock: Clock | None = None) -> None:
        import can

        from lowerbase.clock import RealClock
        from lowerbase.driver.core import DriverCore
        from lowerbase.protocol.codec import default_codec
        from lowerbase.simloop.truth import TruthFollower

        self._can = can
        self.bus = bus
        self.dt = dt
        self.tap = tap
        self.codec = default_codec()
        self._upper_ids = {m.frame_id for m in self.codec if "Lower" not in m.senders}
        self.clock: Clock = clock or RealClock()
        self.t0 = self.clock.now()
        self.cut_until = -math.inf
        self.truth_log = TruthFollower(truth_path) if truth_path is not None else None
        self.driver = DriverCore(self._send, self.clock)
        self._deadline = self.clock.now()
        self.lag: HostLag | None = HostLag()

    def _send(self, frame_id: int, data: bytes) -> None:
        now = self.now()
        if now < self.cut_until:
            return
        with contextlib.suppress(self._can.CanError):
            self.bus.send(self._can.Message(arbitration_id=frame_id, data=data,
                                            is_extended_id=False))
        if self.tap is not None:
            self.tap(now, "upper", frame_id, data)

    def _handle(self, msg: Any) -> tuple[int, bytes] | None:
        frame_id, data = int(msg.arbitration_id), bytes(msg.data)
        if frame_id in self._upper_ids or not is_catalog_frame(msg):
            return None  # our own frames, heard back
        if self.tap is not None:
            self.tap(self.now(), "lower", frame_id, data)
        self.driver.on_frame(frame_id, data)
        return frame_id, data

    def start(self, timeout: float = START_TIMEOUT) -> None:
        """Wait for a Heartbeat; scenario time 0 is the emulator's boot."""
        deadline = self.clock.now() + timeout
        heartbeat = self.codec.message("Heartbeat")
        while self.clock.now() < deadline:
            msg = self.bus.recv(0.1)
            if msg is None:
                continue
            got = self._handle(msg)
            if got is not None and got[0] == heartbeat.frame_id:
                uptime = float(heartbeat.decode(got[1])["Uptime"])
                self.t0 = self.clock.now() - uptime
                self._deadline = self.clock.now()
                return
        raise TransportError(f"no Heartbeat from the emulator within {timeout:g} s")

    def now(self) -> float:
        return self.clock.now() - self.t0

    def step(self) -> None:
        self._deadline += self.dt
        while True:
            remaining = self._deadline - self.clock.now()
            msg = self.bus.recv(remaining if remaining > 0 else 0.0)
            if msg is None:
                break
            self._handle(msg)
        late = self.clock.now() - self._deadline
        if self.lag is not None:
            self.lag.step_started(late)
            # the lower computer's own count of falling behind, as its Heartbeats told the driver
            self.lag.lower_overruns = self.driver.stats["lower_computer_overruns"]
        if late > 1.0:  # suspended or overloaded: no burst (counted late above)
            self._deadline = self.clock.now()
        self.driver.tick()

    def truth(self) -> tuple[float, float, float, float, float] | None:
        if self.truth_log is None:
            return None
        row = self.truth_log.latest()
        return None if row is None else row[1:]

    def pack_soc(self) -> float | None:
        return None

    def apply(self, action: Action) -> None:
        if isinstance(action, FaultAt):
            return  # handed to the emulator at start (--fault SPEC@T+D)
        if isinstance(action, Unplug):
            self.cut_until = action.at + action.duration
            return
        raise ConfigError(f"{action.kind} needs the lower computer in this process")

    def close(self) -> None:
        if self.truth_log is not None:
            self.truth_log.close()


def run_over_bus(scenario: Scenario, workdir: Path, *, tap: FrameTap | None = None,
                 progress: Any = None, bus_config: dict[str, Any] | None = None,
                 on_start: Callable[[Harness], None] | None = None) -> RunResult:
    """Run ``scenario`` against ``lowerbase emulate`` in a child process, in real time.

    ``workdir`` receives ``emulator.log`` and ``truth.csv``. KeyboardInterrupt ends the run
    early (``result.interrupted``); the child is stopped on every way out. ``on_start`` gets
    the harness once the clocks are aligned (e.g. an MCAP recorder attaching to its driver).
    """
    from lowerbase.transport import open_bus

    check_over_bus(scenario)
    workdir.mkdir(parents=True, exist_ok=True)
    config = bus_config or default_bus_config()
    truth_path = workdir / "truth.csv"
    args = [*bus_flags(config), "--soc", f"{scenario.initial.soc:g}",
            "--truth", str(truth_path), "--duration", f"{scenario.duration + 60:g}"]
    if scenario.initial.charger:
        args.append("--charger")
    if scenario.profile is not None:
        args += ["--profile", str(scenario.profile)]
    for fault in scenario.faults:
        args += ["--fault", fault.spec_from_boot()]
    child = EmulatorProcess(args, workdir / "emulator.log")
    harness: BusHarness | None = None
    bus = None
    try:
        child.wait_ready()
        bus = open_bus(config)
        harness = BusHarness(bus, truth_path=truth_path, tap=tap)
        harness.start()
        if on_start is not None:
            on_start(harness)
        result = run_scenario(scenario, harness, mode="processes", progress=progress)
    finally:
        if harness is not None:
            harness.close()
        if bus is not None:
            with contextlib.suppress(Exception):
                bus.shutdown()
        child.stop()
    return result


# -- the terminal ------------------------------------------------------------------------------


class _Line:
    """One line on stderr: rewritten in place on a terminal, else printed every ``period``."""

    def __init__(self, stream: TextIO | None = None, *, force: bool = False,
                 period: float = 5.0) -> None:
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.enabled = self.tty or force
        self.period = period
        self._last_print = -math.inf
        self._shown = False

    def show(self, text: str, t: float) -> None:
        if not self.enabled:
            return
        if self.tty:
            width = shutil.get_terminal_size((100, 20)).columns - 1
            self.stream.write("\r" + text[:width] + "\x1b[K")
            self._shown = True
            self.stream.flush()
        elif t - self._last_print >= self.period:
            self._last_print = t
            self.stream.write(text + "\n")
            self.stream.flush()

    def done(self) -> None:
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = False


class ProgressBar(_Line):
    """``[#####.....]  50 %  t 5.0/10.0 s`` for long runs."""

    def __init__(self, duration: float, stream: TextIO | None = None, *,
                 force: bool = False) -> None:
        super().__init__(stream, force=force, period=max(duration / 10, 1.0))
        self.duration = duration

    def __call__(self, t: float, harness: Harness) -> None:
        frac = min(max(t / self.duration, 0.0), 1.0)
        bar = "#" * round(frac * 30)
        self.show(f"[{bar:<30}] {frac * 100:3.0f} %  t {t:5.1f}/{self.duration:g} s", t)


def status_text(t: float, harness: Harness) -> str:
    """t, pose (/odom), speed, SOC, robot state and StatusCode names, on one line."""
    from lowerbase.protocol.status_codes import describe

    d = harness.driver
    x, y, yaw = d.ekf.pose
    v, w = d.measured_twist
    battery = d.bms.battery_fields()
    soc = f"{battery['batteryPercentage']:.0f}%" if battery else "-"
    state = d.system_status.get("RobotState")
    state_name = ROBOT_STATES[state] if isinstance(state, int) and state < len(
        ROBOT_STATES) else d.state.value
    bits = ", ".join(describe(d.status_code)) or "ok"
    return (f"t {t:5.1f} s  x {x:+5.2f} y {y:+5.2f} m {math.degrees(yaw):+4.0f}°  "
            f"v {v:+4.2f} m/s w {w:+4.2f} rad/s  SOC {soc}  {state_name}  {bits}")


class StatusLine(_Line):
    """The demo's live line (see :func:`status_text`)."""

    def __call__(self, t: float, harness: Harness) -> None:
        self.show(status_text(t, harness), t)


def task_status_text(t: float, sim: Any) -> str:
    """A task run on one line: t, the true pose, SOC and current (the BMS as the driver reads
    it), the task and its action, robot_state and the status message."""
    from lowerbase.scenarios.tasks import FIELDS

    x, y, _ = sim.world.true_pose()
    snap = sim.world.loop.driver.bms.snapshot()
    battery = f"SOC {snap.soc:.0f}% {snap.current:+5.1f} A" if snap is not None else "SOC -"
    st = sim.machine.tracker.current
    if st is None:
        return f"t {t:6.1f} s  x {x:5.2f} y {y:5.2f} m  {battery}"

    def name(field: str) -> str:
        try:
            return FIELDS[field](int(getattr(st, field))).name.lower()
        except ValueError:
            return str(getattr(st, field))

    task = f"task {st.task_id} {name('task_state')}, {name('action_type')}" if st.task_type \
        else "no task"
    msg = f"  {st.msg}" if st.msg else ""
    return (f"t {t:6.1f} s  x {x:5.2f} y {y:5.2f} m  {battery}  {task}  "
            f"robot {name('robot_state')}{msg}")


class TaskStatusLine(_Line):
    """The task demo's live line (see :func:`task_status_text`)."""

    def __call__(self, t: float, sim: Any) -> None:
        self.show(task_status_text(t, sim), t)
