"""Run a :class:`~lowerbase.scenarios.wheeled.Scenario` and sample its :class:`Trace`.

One loop, two harnesses:

* :class:`SimHarness`: the MCU and the DriverCore back to back in a :class:`SimLoop` on a
  simulated clock, as fast as the CPU allows (~30-100x real time), or paced to the wall clock
  (``realtime=True``: the same SimLoop, each step waits for its real-time deadline, so a run
  looks like the real thing while staying deterministic).
* ``lowerbase.scenarios.demo.BusHarness``: the lower computer is ``lowerbase emulate`` in another
  process and the DriverCore talks to it over a python-can bus, in real time.

Every control period the runner fires the timeline's due actions, re-publishes the active
twist at 20 Hz, steps the harness and, every ``sample_period``, appends a sample (truth,
/odom_raw, /odom, measured and commanded twist, battery, StatusCode, states) to the trace.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from lowerbase.driver.core import DriverCore
from lowerbase.errors import ConfigError
from lowerbase.scenarios.expect import Outcome, Trace
from lowerbase.scenarios.lag import HostLag
from lowerbase.scenarios.timeline import (
    LINK_STATES,
    TWIST_PERIOD,
    Action,
    Charger,
    ClearFault,
    Control,
    FaultAt,
    Led,
    ParamWrite,
    Slip,
    Twist,
    Unplug,
)
from lowerbase.scenarios.wheeled import Scenario
from lowerbase.simloop.loop import SimLoop

#: (t [s], "lower"|"upper", frame id, data): every frame of a run, for recording
FrameTap = Callable[[float, str, int, bytes], None]


class Harness(Protocol):
    """The lower computer and the driver, however they are connected."""

    driver: DriverCore
    dt: float  #: [s] one step
    lag: HostLag | None  #: how late the host kept a run on the wall clock (None: simulated)

    def now(self) -> float:
        """Scenario time [s]."""
        ...

    def step(self) -> None:
        """Advance one period: frames both ways, the driver's tick."""
        ...

    def truth(self) -> tuple[float, float, float, float, float] | None:
        """True (x, y, yaw, v, w) now, or None when not known."""
        ...

    def pack_soc(self) -> float | None:
        """The pack model's exact SOC [%], or None when not in this process."""
        ...

    def apply(self, action: Action) -> None:
        """Actions that are not driver calls: faults, charger, slip, unplug."""
        ...

    def close(self) -> None: ...


# -- the simulated harness ---------------------------------------------------------------------


class _BenchLoop(SimLoop):
    """SimLoop whose upper -> lower direction can be cut (a bench pulling the cable)."""

    cut_until = -math.inf  #: [s] frames from the driver are lost until then

    def _from_driver(self, frame_id: int, data: bytes) -> None:
        if self.clock.now() < self.cut_until:
            return
        super()._from_driver(frame_id, data)


class SimHarness:
    """SimLoop on its simulated clock; ``realtime`` paces it to the wall clock."""

    def __init__(self, scenario: Scenario, *, tap: FrameTap | None = None,
                 realtime: bool = False) -> None:
        from lowerbase.firmware_model.profile import load_profile

        profile = load_profile(scenario.profile)
        self.loop = _BenchLoop(profile, soc=scenario.initial.soc, tap=tap)
        self.driver = self.loop.driver
        self.dt = self.loop.mcu.dt
        self.realtime = realtime
        self.lag: HostLag | None = HostLag() if realtime else None
        self._wall0: float | None = None
        pose = scenario.initial.pose
        truth = self.loop.mcu.truth
        truth.x, truth.y, truth.yaw = pose.x, pose.y, pose.yaw
        if scenario.initial.charger:
            self.loop.mcu.bms.connect_charger()
        self.world: Any = None  # WorldSim of a [world] table (scenario_world.py)
        if scenario.world is not None:
            from lowerbase.world.sim import WorldSim

            self.world = WorldSim(scenario.world.config(), loop=self.loop)
        self.world_names: tuple[str, ...] = scenario.world.contact_names if self.world else ()

    def now(self) -> float:
        return self.loop.now

    def step(self) -> None:
        if self.world is not None:
            self.world.step()
        else:
            self.loop.step()
        if self.realtime:
            if self._wall0 is None:
                self._wall0 = time.monotonic() - self.loop.now
            delay = self._wall0 + self.loop.now - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif self.lag is not None:  # the same results, later than the wall clock
                self.lag.step_started(-delay)

    def truth(self) -> tuple[float, float, float, float, float] | None:
        t = self.loop.mcu.truth
        return t.x, t.y, t.yaw, t.v, t.w

    def pack_soc(self) -> float | None:
        device = getattr(self.loop.mcu.bms, "device", None)
        return float(device.pack.soc) if device is not None else None

    def apply(self, action: Action) -> None:
        mcu = self.loop.mcu
        if isinstance(action, FaultAt):
            mcu.inject(action.fault)
        elif isinstance(action, ClearFault):
            mcu.clear_fault(action.fault_kind)
        elif isinstance(action, Charger):
            if action.connected:
                mcu.bms.connect_charger()
            else:
                mcu.bms.disconnect_charger()
        elif isinstance(action, Slip):
            from lowerbase.firmware_model.truth import SlipEvent

            # slip events run on time since boot, like faults
            mcu.slip.add_event(SlipEvent(action.wheel, self.loop.now - mcu.boot_time,  # type: ignore[arg-type]
                                         action.duration, action.fraction))
        elif isinstance(action, Unplug):
            self.loop.cut_until = action.at + action.duration
        else:  # pragma: no cover - the runner sends the others itself
            raise ConfigError(f"cannot apply {action.kind}")

    def close(self) -> None:
        self.loop.mcu.shutdown()


# -- the run -----------------------------------------------------------------------------------


@dataclass
class RunResult:
    scenario: Scenario
    trace: Trace
    outcomes: list[tuple[Any, Outcome]]
    mode: str  #: "simulated", "realtime" or "processes"
    wall_time: float  #: [s]
    events: list[tuple[float, str]] = field(default_factory=list)  #: (t, label) as fired
    interrupted: bool = False
    lag: HostLag | None = None  #: on the wall clock: how far the host kept the run late

    @property
    def passed(self) -> bool:
        return not self.interrupted and all(o.passed for _, o in self.outcomes)


Progress = Callable[[float, Harness], None]


class _Publisher:
    """Twist segments: the latest started one is published every TWIST_PERIOD."""

    def __init__(self) -> None:
        self.active: Twist | None = None
        self.next_at = -math.inf

    def start(self, twist: Twist, now: float) -> None:
        self.active = twist
        self.next_at = now

    def command(self) -> tuple[float, float]:
        return (self.active.linear, self.active.angular) if self.active else (0.0, 0.0)

    def publish(self, driver: DriverCore, now: float) -> None:
        twist = self.active
        if twist is None:
            return
        if now >= twist.end - 1e-9:
            if twist.stop:
                driver.set_twist(0.0, 0.0, twist.smoothed)
            self.active = None
            return
        if now >= self.next_at - 1e-9:
            driver.set_twist(twist.linear, twist.angular, twist.smoothed)
            self.next_at += TWIST_PERIOD


def run_scenario(scenario: Scenario, harness: Harness, *, mode: str = "simulated",
                 progress: Progress | None = None, progress_period: float = 0.25) -> RunResult:
    """Run ``scenario`` to its end on ``harness``; evaluate its expectations.

    ``progress(t, harness)`` is called every ``progress_period`` [s] of scenario time.
    KeyboardInterrupt ends the run early (``interrupted``); the trace so far is kept.
    """
    wall0 = time.monotonic()
    trace = Trace()
    driver = harness.driver
    pending = list(scenario.timeline)
    publisher = _Publisher()
    events: list[tuple[float, str]] = []
    pose = scenario.initial.pose
    if not pose.is_origin:
        driver.ekf.reset(pose.x, pose.y, pose.yaw)

        placed: list[bool] = []

        def _place(what: str, core: DriverCore) -> None:
            # the odometry exists once the driver is configured; start it at the initial pose
            # (once: after a reboot the odometry keeps its pose)
            if what == "ready" and core.odometry is not None and not placed:
                core.odometry.reset(pose.x, pose.y, pose.yaw)
                placed.append(True)

        driver.listeners.append(_place)
    next_sample = 0.0
    next_progress = 0.0
    interrupted = False
    try:
        while True:
            now = harness.now()
            while pending and pending[0].at <= now + 1e-9:
                action = pending.pop(0)
                events.append((now, action.label()))
                _fire(action, harness, publisher, now)
            publisher.publish(driver, now)
            if now >= next_sample - 1e-9:
                trace.append(_sample(now, harness, publisher))
                next_sample += scenario.sample_period
            if progress is not None and now >= next_progress - 1e-9:
                progress(now, harness)
                next_progress += progress_period
            if now >= scenario.duration - 1e-9:
                break
            harness.step()
    except KeyboardInterrupt:
        interrupted = True
    outcomes = [(exp, exp.evaluate(trace)) for exp in scenario.expectations]
    return RunResult(scenario, trace, outcomes, mode, time.monotonic() - wall0, events,
                     interrupted, harness.lag)


def _fire(action: Action, harness: Harness, publisher: _Publisher, now: float) -> None:
    driver = harness.driver
    if isinstance(action, Twist):
        publisher.start(action, now)
    elif isinstance(action, Control):
        driver.control(action.command)
    elif isinstance(action, Led):
        driver.set_led(action.strip, action.submodule, action.urgency, action.abnormal,
                       action.normal, action.color)
    elif isinstance(action, ParamWrite):
        driver.write_parameter(action.name, action.value)
    else:
        harness.apply(action)


def _sample(now: float, harness: Harness, publisher: _Publisher) -> dict[str, float]:
    d = harness.driver
    s: dict[str, float] = {"t": now}
    truth = harness.truth()
    if truth is not None:
        s.update(zip(("truth_x", "truth_y", "truth_yaw", "truth_v", "truth_w"), truth,
                     strict=True))
    odo = d.odometry
    if odo is not None and odo.has_baseline:
        s.update(raw_x=odo.x, raw_y=odo.y, raw_yaw=odo.yaw)
        s.update(zip(("ekf_x", "ekf_y", "ekf_yaw"), d.ekf.pose, strict=True))
    s["meas_v"], s["meas_w"] = d.measured_twist
    s["cmd_v"], s["cmd_w"] = publisher.command()
    battery = d.bms.battery_fields()
    if battery is not None:
        s["soc"] = float(battery["batteryPercentage"])
        s["voltage"] = float(battery["batteryVoltage"])
        s["current"] = float(battery["batteryCurrent"])
        if battery["capacityFull"] > 0:  # finer than the integer SOC, also over a bus
            s["capacity_soc"] = 100.0 * battery["capacityRemain"] / battery["capacityFull"]
    pack = harness.pack_soc()
    if pack is not None:
        s["pack_soc"] = pack
    s["status"] = float(d.status_code)
    s["robot_state"] = float(d.system_status.get("RobotState", -1))
    s["link"] = float(LINK_STATES.index(d.state.value))
    s["reboots"] = float(d.reboots)
    world = getattr(harness, "world", None)
    if world is not None:
        from lowerbase.scenarios.world import world_sample

        s.update(world_sample(world, harness.world_names))  # type: ignore[attr-defined]
    return s


def run_simulated(scenario: Scenario, *, tap: FrameTap | None = None, realtime: bool = False,
                  progress: Progress | None = None) -> RunResult:
    """Run on a SimLoop (simulated clock, or paced to real time)."""
    harness = SimHarness(scenario, tap=tap, realtime=realtime)
    try:
        return run_scenario(scenario, harness, mode="realtime" if realtime else "simulated",
                            progress=progress)
    finally:
        harness.close()
