"""What every check gets: the client, the settings, shared state and helpers to drive
the lower computer (states, motion, parameters, the one reboot)."""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import can

from lowerbase.conformance.catalog import parameter_index
from lowerbase.conformance.client import ConformanceClient, RawFrame
from lowerbase.conformance.core import CheckFailed, CheckSkipped, Outcome, Settings, require
from lowerbase.conformance.lower_client import Received
from lowerbase.protocol.codec import MessageCodec

# -- the context --------------------------------------------------------------------------------

#: RobotState and ControlMode numbers (the catalog's value tables)
BOOT, STANDBY, ACTIVE, EMERGENCY_STOP, FAULT = range(5)
CONTROL_CAN = 1
STILL = 0.2  #: a MotionState |Linear| below STILL * Settings.speed counts as standing still
MOTION_PERIOD = 0.02  #: [s] MotionCommand cycle the suite keeps while driving
#: [s] a SystemStatus received this long after a ControlCommand reflects it (frames in flight)
SETTLE = 0.03


def overrun_steps(a: dict[str, Any], b: dict[str, Any]) -> int | None:
    """The slips of its time (Heartbeat.Overruns steps, mod 16: its own count of falling
    behind real time) the lower computer reports from Heartbeat values ``a`` to ``b``; None
    when a reboot lies between them (BootCounter changed)."""
    if a.get("BootCounter") != b.get("BootCounter"):
        return None
    return (int(b.get("Overruns", 0)) - int(a.get("Overruns", 0))) % 16


class Context:
    """What every check gets: the client, the settings, and state shared between checks."""

    def __init__(self, client: ConformanceClient, settings: Settings) -> None:
        self.client = client
        self.codec = client.codec
        self.settings = settings
        self.t_start = time.monotonic()
        self.window_end = self.t_start + settings.observe
        self.linked = False
        self.param_cache: dict[int, float] = {}  #: index -> value read
        self.to_restore: dict[int, float] = {}  #: index -> value to write back at the end
        self.versions: dict[int, str] = {}
        #: measurements shared by the checks of one family (e.g. the physics segments)
        self.shared: dict[str, Any] = {}
        self._reboot: tuple[float, Received] | CheckFailed | None = None
        self._last_control = -math.inf  #: time.monotonic() of the last ControlCommand

    # timing helpers

    def wait_until(self, condition: Callable[[], bool], timeout: float, poll: float = 0.02
                   ) -> bool:
        """Poll ``condition`` until it holds or ``timeout`` [s] passes."""
        deadline = time.monotonic() + timeout
        while True:
            if condition():
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(poll)

    def connect(self) -> None:
        """Wait (bounded) until any frame of the lower computer arrives, and until it has
        finished booting (it ignores requests while booting)."""
        self.linked = self.wait_until(lambda: bool(self.client.raw), self.settings.link_timeout)
        if self.linked:
            self.client.expect("SystemStatus", lambda v: v["RobotState"] != BOOT, since=0.0,
                               timeout=self.settings.boot_timeout)

    def observation(self, msg: MessageCodec) -> list[RawFrame]:
        """Frames of ``msg`` in the observation window (waits for the window to end)."""
        delay = self.window_end - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        return self.client.raw_frames(msg.frame_id, self.t_start, self.window_end)

    # state

    def latest(self, name: str, timeout: float | None = None) -> Received:
        """The newest ``name`` frame (waiting up to ``timeout``, default 2 cycles + 0.5 s)."""
        got = self.client.latest(name)
        if got is None:
            cycle = self.codec.message(name).cycle_time or 0.0
            wait = 2 * cycle + 0.5 if timeout is None else timeout
            got = self.client.expect(name, timeout=wait, since=0.0)
        require(got is not None, f"no {name} from the lower computer")
        assert got is not None
        return got

    def time_slipped(self, t0: float, t1: float) -> bool | None:
        """Whether the lower computer reports that its time slipped in [t0, t1] (reception
        times): Heartbeat.Overruns (its own count of falling behind real time) differs between
        its last Heartbeat before t0 and its first after t1 (waited for: two cycles at most).
        None when they are not both there to tell, or a reboot lies between them (the reboot
        checks' finding)."""
        cycle = self.codec.message("Heartbeat").cycle_time or 0.5
        before = [f for f in self.client.frames("Heartbeat", t0 - 2 * cycle) if f.t <= t0]
        after = self.client.expect("Heartbeat", timeout=2 * cycle, since=t1)
        if not before or after is None:
            return None
        steps = overrun_steps(before[-1].values, after.values)
        return None if steps is None else steps != 0

    def state(self) -> int:
        """RobotState from a SystemStatus that reflects the last ControlCommand sent."""
        since = self._last_control + SETTLE
        got = self.client.latest("SystemStatus")
        if got is None or got.t < since:
            cycle = self.codec.message("SystemStatus").cycle_time or 0.0
            got = self.client.expect("SystemStatus", since=since,
                                     timeout=2 * cycle + self.settings.reply_timeout)
        require(got is not None, "no SystemStatus from the lower computer")
        assert got is not None
        return int(got.values["RobotState"])

    def state_name(self, state: int) -> str:
        return self.codec.message("SystemStatus").signal("RobotState").choices.get(
            state, str(state))

    def control(self, command: str) -> float:
        """Send ControlCommand ``command``; returns the send time."""
        t = time.monotonic()
        self.client.send("ControlCommand", Command=command)
        self._last_control = t
        return t

    def expect_state(self, predicate: Callable[[dict[str, Any]], bool], since: float,
                     timeout: float | None = None) -> Received | None:
        return self.client.expect("SystemStatus", predicate, since=since,
                                  timeout=self.settings.reply_timeout if timeout is None
                                  else timeout)

    # The command is sent even when the state seems right already: a SystemStatus in flight
    # may be older than the last command, and commands are handled in the order sent.

    def ensure_standby(self) -> None:
        t = self.control("Standby")
        if not self.expect_state(lambda v: v["RobotState"] == STANDBY, t):
            raise CheckFailed(f"cannot reach Standby from {self.state_name(self.state())}")

    def ensure_active(self) -> None:
        t = self.control("EnableCanControl")
        if not self.expect_state(lambda v: v["RobotState"] == ACTIVE, t):
            raise CheckFailed(f"cannot enable from {self.state_name(self.state())}")

    def require_motion(self) -> None:
        if not self.settings.motion:
            raise CheckSkipped("turns the wheels (--no-motion)")

    @contextmanager
    def driving(self, linear: float, angular: float = 0.0) -> Iterator[MotionSender]:
        """Send MotionCommand every 20 ms in the background while the block runs."""
        sender = MotionSender(self.client, linear, angular)
        sender.start()
        try:
            yield sender
        finally:
            sender.stop()

    def wait_moving(self, timeout: float = 2.0) -> Received | None:
        """The first MotionState from now with Linear at least half the suite's speed."""
        half = 0.5 * self.settings.speed
        return self.client.expect("MotionState", lambda v: v["Linear"] >= half, timeout=timeout)

    def wait_still(self, since: float, timeout: float) -> Received | None:
        limit = STILL * self.settings.speed
        return self.client.expect(
            "MotionState", lambda v: abs(v["Linear"]) < limit and abs(v["Angular"]) < limit * 5,
            timeout=timeout, since=since)

    def max_speed(self, since: float, until: float = math.inf) -> float:
        """Largest |MotionState.Linear| received in [since, until] [m/s]."""
        return max((abs(f.values["Linear"]) for f in self.client.frames("MotionState", since)
                    if f.t <= until), default=0.0)

    def status_code(self, since: float = 0.0, timeout: float | None = None) -> int:
        """The newest StatusCode received after ``since`` (waiting for one)."""
        got = self.client.expect("StatusCode", since=since, timeout=self.settings.reply_timeout
                                 if timeout is None else timeout)
        require(got is not None, "no StatusCode")
        assert got is not None
        newest = self.client.latest("StatusCode")
        return int((newest or got).values["Code"])

    # requests

    def parameter_request(self, index: int, value: float | None = None) -> Received | None:
        """Read (``value`` None) or write a parameter; the ParameterResponse or None."""
        op = 0 if value is None else 1
        t = time.monotonic()
        self.client.send("ParameterRequest", Index=index, Op=op,
                         Value=0.0 if value is None else value)
        return self.client.expect(
            "ParameterResponse", lambda v: v["Index"] == index and v["Op"] == op, since=t,
            timeout=self.settings.reply_timeout)

    def parameter(self, name: str) -> float:
        """A parameter's value by name (read once, then cached)."""
        index = parameter_index(self.codec, name)
        if index not in self.param_cache:
            reply = self.parameter_request(index)
            require(reply is not None and reply.values["Result"] == 0,
                    f"cannot read parameter {name}")
            assert reply is not None
            self.param_cache[index] = float(reply.values["Value"])
        return self.param_cache[index]

    def reboot(self) -> tuple[float, Received]:
        """Reboot the lower computer once per run: (send time, the boot-up Heartbeat)."""
        if self._reboot is None:
            try:
                self._reboot = self._do_reboot()
            except CheckFailed as exc:
                self._reboot = exc
        if isinstance(self._reboot, CheckFailed):
            raise self._reboot
        return self._reboot

    def _do_reboot(self) -> tuple[float, Received]:
        boot = int(self.latest("Heartbeat").values["BootCounter"])
        t = self.control("Reboot")
        hb = self.client.expect("Heartbeat", lambda v: v["BootCounter"] != boot, since=t,
                                timeout=self.settings.boot_timeout)
        require(hb is not None, f"no Heartbeat with a new BootCounter within "
                f"{self.settings.boot_timeout:g} s of ControlCommand Reboot", boot_counter=boot)
        assert hb is not None
        self.param_cache.clear()  # a reboot reloads the stored parameters
        return t, hb

    def finish(self) -> list[str]:
        """Restore parameters the suite changed and leave the robot in standby; problems."""
        problems = []
        for index, value in sorted(self.to_restore.items()):
            reply = self.parameter_request(index, value)
            if reply is None or reply.values["Result"] != 0:
                problems.append(f"parameter {index} could not be restored to {value:g}")
        self.to_restore.clear()
        if self.linked:
            self.control("Standby")
        return problems


#: a chassis conformance check: what it does on the robot's context
CheckFunc = Callable[[Context], Outcome]


class MotionSender:
    """A background thread sending one MotionCommand every 20 ms, as a driver does."""

    def __init__(self, client: ConformanceClient, linear: float, angular: float) -> None:
        self.client = client
        self.linear, self.angular = linear, angular
        self.last_sent = -math.inf  #: time.monotonic() of the last MotionCommand
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="conformance-motion",
                                        daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        deadline = time.monotonic()
        while not self._stop.is_set():
            # a full transmit queue is no reason to stop: the next period tries again
            with contextlib.suppress(can.CanError):
                self.client.send("MotionCommand", Linear=self.linear, Angular=self.angular,
                                 Mode="Raw")
            self.last_sent = time.monotonic()
            self.sent += 1
            deadline += MOTION_PERIOD
            self._stop.wait(max(0.0, deadline - time.monotonic()))

    def stop(self) -> float:
        """Stop sending; returns the time of the last MotionCommand."""
        self._stop.set()
        self._thread.join(timeout=1.0)
        return self.last_sent
