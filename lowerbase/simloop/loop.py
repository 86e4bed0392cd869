"""The emulated lower computer and the driver core wired back to back on one simulated clock.

No bus, no ROS, no threads: each control period the MCU steps, its frames reach the driver
core with their send time, the driver ticks, and its frames reach the MCU. What the driver
would publish (/odom_raw, /odom, /battery, ...) is read off ``loop.driver``; the ground truth
off ``loop.mcu.truth``. Scenarios, the demo and the odometry benchmark run on this.

``run`` and ``drive`` without an ``on_step`` (and :meth:`SimLoop.advance`) run 1 to
``MAX_BATCH`` periods at once: the driver's ticks first, each at its period's time (what they
send, MotionCommands, depends on the twist and the command grid alone, not on the frames they
would have seen), their sends handed to one ``Mcu.advance(k, incoming)`` (a repeated command
stays inside its compiled run), the MCU's frames to the driver as they are sent, each at its
period's time: the frames, /odom and the commands of ``k`` single steps, bit for bit. Only
while nothing else can make the driver send: the link READY and not silent for any of the
ticks, no listener, no tap, no fault in the MCU, nothing but MotionCommands pending for it.

``surroundings`` (a :class:`~lowerbase.firmware_model.truth.Surroundings`, e.g. the world's
footprint contact) is what the robot can bump into; None (the default): open floor.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

from lowerbase.clock import SimClock
from lowerbase.driver.core import DriverConfig, DriverCore, LinkState
from lowerbase.firmware_model.faults import Fault
from lowerbase.firmware_model.mcu import Mcu, RobotState
from lowerbase.firmware_model.profile import Profile, load_profile
from lowerbase.firmware_model.truth import Surroundings

FrameTap = Callable[[float, str, int, bytes], None]

#: at most this many periods per Mcu.advance call
MAX_BATCH = 256


class _DriverClock:
    """The loop's clock as the driver core reads it: the loop's own, or pinned to a period's
    time while that period's frames and tick are handed to the driver after a batch."""

    is_simulated = True

    def __init__(self, base: SimClock) -> None:
        self.base = base
        self.pinned: float | None = None

    def now(self) -> float:
        return self.base.now() if self.pinned is None else self.pinned

    def sleep_until(self, deadline: float) -> None:
        self.base.sleep_until(deadline)


L = TypeVar("L", bound="SteppedLoop")
T = TypeVar("T", bound="TickedLoop")


class TickedLoop:
    """run/run_until for the loops above the chassis (NavSim, TaskSim): a subclass gives
    ``tick()`` (one control period of its own) and ``now`` [s]."""

    @property
    def now(self) -> float:
        raise NotImplementedError

    def tick(self) -> object:
        raise NotImplementedError

    def run(self, seconds: float) -> None:
        """Tick for ``seconds`` of simulated time."""
        end = self.now + seconds
        while self.now < end - 1e-9:
            self.tick()

    def run_until(self: T, condition: Callable[[T], bool], timeout: float) -> bool:
        """Tick until ``condition`` holds (True) or ``timeout`` [s] of simulated time passes."""
        end = self.now + timeout
        while self.now < end - 1e-9:
            if condition(self):
                return True
            self.tick()
        return condition(self)



class SteppedLoop:
    """Runs a simulated loop forward; a subclass gives ``step()``, ``now`` [s], ``control_dt``
    [s] (one step) and ``twist_driver`` (the driver core that takes twists)."""

    control_dt: float
    twist_driver: DriverCore

    @property
    def now(self) -> float:
        raise NotImplementedError

    def step(self) -> None:
        raise NotImplementedError

    def advance(self, periods: int) -> None:
        """``periods`` steps (SimLoop: batched where that changes nothing)."""
        for _ in range(periods):
            self.step()

    def run(self: L, seconds: float, on_step: Callable[[L], None] | None = None) -> None:
        periods = round(seconds / self.control_dt)
        if on_step is None:
            self.advance(periods)
            return
        for _ in range(periods):
            self.step()
            on_step(self)

    def run_until(self: L, condition: Callable[[L], bool], timeout: float) -> bool:
        """Step until ``condition`` holds (True) or ``timeout`` [s] of simulated time passes."""
        end = self.now + timeout
        while self.now < end:
            if condition(self):
                return True
            self.step()
        return condition(self)

    def drive(self: L, linear: float, angular: float, seconds: float, smoothed: bool = False,
              on_step: Callable[[L], None] | None = None) -> None:
        """Publish a twist at 20 Hz (as a navigation stack does) for ``seconds``."""
        every = max(1, round(0.05 / self.control_dt))
        periods = round(seconds / self.control_dt)
        if on_step is None:
            for k in range(0, periods, every):
                self.twist_driver.set_twist(linear, angular, smoothed)
                self.advance(min(every, periods - k))
            return
        for k in range(periods):
            if k % every == 0:
                self.twist_driver.set_twist(linear, angular, smoothed)
            self.step()
            on_step(self)


class SimLoop(SteppedLoop):
    def __init__(
        self,
        profile: Profile | None = None,
        *,
        faults: Iterable[Fault | str] = (),
        bms: Any = "own",
        driver_config: DriverConfig | None = None,
        params_path: str | None = None,
        soc: float = 80.0,
        tap: FrameTap | None = None,
        surroundings: Surroundings | None = None,
    ) -> None:
        self.profile = profile or load_profile()
        self.clock = SimClock()
        self.tap = tap
        self._to_driver: list[tuple[float, int, bytes]] = []
        self._to_mcu: list[tuple[int, bytes]] = []
        if bms == "own":
            from lowerbase.bms.adapter import McuBmsAdapter

            bms = McuBmsAdapter.from_profile(self.profile, soc=soc)
        self.mcu = Mcu(self.profile, self.clock, self._from_mcu, params_path=params_path,
                       bms=bms, faults=faults)
        self._driver_clock = _DriverClock(self.clock)
        self.driver = DriverCore(self._from_driver, self._driver_clock, driver_config)
        #: periods run in batches, batches, and driver sends that fell inside a batch (never
        #: expected: the conditions in _batchable exclude them; then no more batches)
        self.batch_stats = {"periods": 0, "batches": 0, "mistimed": 0}
        #: in a batch: the driver's on_frame (frames go straight to it), the last period's time
        self._direct: Callable[[int, bytes, float], None] | None = None
        self._last_of_batch = 0.0
        #: while the driver's ticks of a batch run ahead: their sends, (period, id, data)
        self._ahead: list[tuple[int, int, bytes]] | None = None
        self._ahead_period = 0
        self.control_dt = self.mcu.dt
        self.twist_driver = self.driver
        self.mcu.truth.surroundings = surroundings
        self._motion_id = self.driver.codec.message("MotionCommand").frame_id
        #: the driver's listeners only read (publish what a frame completed, never send or
        #: set a twist): they do not keep periods from running in batches, where they are
        #: called at each frame's period time, the driver's clock pinned there
        self.passive_listeners = False

    @property
    def surroundings(self) -> Surroundings | None:
        """What the robot can collide with (asked by the ground-truth integrator each step)."""
        return self.mcu.truth.surroundings

    @surroundings.setter
    def surroundings(self, value: Surroundings | None) -> None:
        self.mcu.truth.surroundings = value

    def _from_mcu(self, frame_id: int, data: bytes) -> None:
        now = self.clock.now()
        if self._direct is not None:  # in a batch: straight to the driver
            self._direct(frame_id, data, now)
            return
        self._to_driver.append((now, frame_id, data))
        if self.tap is not None:
            self.tap(now, "lower", frame_id, data)

    def _from_driver(self, frame_id: int, data: bytes) -> None:
        if self._ahead is not None:  # a tick run ahead: the MCU takes it before that period
            self._ahead.append((self._ahead_period, frame_id, data))
            return
        self._to_mcu.append((frame_id, data))
        if self._direct is not None and self.clock.now() < self._last_of_batch:
            self.batch_stats["mistimed"] += 1  # in a batch, before its last period
        if self.tap is not None:
            self.tap(self._driver_clock.now(), "upper", frame_id, data)

    @property
    def now(self) -> float:
        return self.clock.now()

    def step(self) -> None:
        """One control period of the lower computer, with the driver in the loop."""
        for frame_id, data in self._to_mcu:
            self.mcu.receive(frame_id, data)
        self._to_mcu.clear()
        self.mcu.step()
        frames, self._to_driver = self._to_driver, []
        driver = self.driver
        on_frame = driver.on_frame
        for stamp, frame_id, data in frames:
            on_frame(frame_id, data, stamp)
        driver.tick()
        self.clock.advance(self.mcu.dt)

    def advance(self, periods: int) -> None:
        """``periods`` control periods: what as many :meth:`step` calls do, frame for frame
        and bit for bit, with runs of periods in which the driver cannot send in one
        ``Mcu.advance`` (see the module docstring)."""
        while periods > 0:
            k = self._batchable(periods)
            if k < 1:
                self.step()
                periods -= 1
            else:
                self._batch(k)
                periods -= k

    def drive(self, linear: float, angular: float, seconds: float, smoothed: bool = False,
              on_step: Callable[[SimLoop], None] | None = None) -> None:
        """:meth:`SteppedLoop.drive`; without ``on_step`` the twists every 50 ms are set
        inside the batches too (before their periods, as the ticks run ahead): one batch spans
        many of them."""
        if on_step is not None or self.twist_driver is not self.driver:
            super().drive(linear, angular, seconds, smoothed, on_step)
            return
        every = max(1, round(0.05 / self.control_dt))
        periods = round(seconds / self.control_dt)
        done = 0
        while done < periods:
            k = self._batchable(periods - done)
            if k < 1:
                if done % every == 0:
                    self.driver.set_twist(linear, angular, smoothed)
                self.step()
                done += 1
            else:
                self._batch(k, (done, every, linear, angular, smoothed))
                done += k

    def _batchable(self, periods: int) -> int:
        """How many periods from now may run as one batch: up to and including the first
        whose driver tick may do anything; 0 when anything but the tick could make the driver
        send (or the MCU take something else than a MotionCommand): :meth:`step` then. A
        single period is a batch too (the lockstep robot's jobs cut many runs to one period:
        the compiled run's call costs less than a step's)."""
        driver, mcu = self.driver, self.mcu
        if (driver.state is not LinkState.READY
                or (driver.listeners and not self.passive_listeners)
                or self.tap is not None or mcu.faults or mcu._delayed
                or mcu.state is not RobotState.ACTIVE or driver.heard_until is not None
                or driver._reboot_suspect is not None or self.batch_stats["mistimed"]
                or type(self).step is not SimLoop.step):
            return 0
        for frame_id, _ in self._to_mcu:
            if frame_id != self._motion_id:
                return 0
        return driver.quiet_ticks(self.clock.now(), mcu.dt, min(periods, MAX_BATCH))

    def _batch(self, k: int,
               twists: tuple[int, int, float, float, bool] | None = None) -> None:
        """``k`` periods: the driver's ``k`` ticks first, each at its period's time, their
        sends (MotionCommands: they read only the twist, the command grid and the link's
        Heartbeat time, which no frame of a READY link's batch moves the wrong way) kept as
        the MCU's ``incoming`` before the next period (the last tick's after the batch); then
        the MCU in one advance, its frames handed to the driver as they are sent, each at its
        period's time. ``twists`` (first period's index, every, linear, angular, smoothed): a
        twist set before each period whose index is a multiple of ``every``. A frame that
        would have changed what a tick sends (a reboot: the link configuring, an enable
        wanted) or a send while a frame is handled is counted in ``batch_stats["mistimed"]``
        and ends batching (never expected: see _batchable)."""
        mcu, clock, driver, pin = self.mcu, self.clock, self.driver, self._driver_clock
        incoming = [(0, frame_id, data) for frame_id, data in self._to_mcu]
        self._to_mcu.clear()
        ahead: list[tuple[int, int, bytes]] = []
        self._ahead = ahead
        now = clock.now()
        try:
            for j in range(1, k + 1):
                pin.pinned = now  # as the clock advances
                if twists is not None and (twists[0] + j - 1) % twists[1] == 0:
                    self._ahead_period = j - 1
                    driver.set_twist(*twists[2:])
                self._ahead_period = j
                driver.tick()
                now += mcu.dt
        finally:
            self._ahead = None
            pin.pinned = None
        for sent in ahead:
            if sent[0] < k:
                incoming.append(sent)
            else:
                self._to_mcu.append(sent[1:])
        self._last_of_batch = math.inf  # any send from now on is out of its place
        self._direct = driver.on_frame
        try:
            mcu.advance(k, incoming)
        finally:
            self._direct = None
        if driver.state not in (LinkState.READY, LinkState.STANDBY) or driver._enable_wanted:
            self.batch_stats["mistimed"] += 1  # its ticks would have sent something else
        self.batch_stats["periods"] += k
        self.batch_stats["batches"] += 1
