"""The emulated lower computer and the driver core wired back to back on one simulated clock.

No bus, no ROS, no threads: each control period the MCU steps, its frames reach the driver
core with their send time, the driver ticks, and its frames reach the MCU. What the driver
would publish (/odom_raw, /odom, /battery, ...) is read off ``loop.driver``; the ground truth
off ``loop.mcu.truth``. Scenarios, the demo and the odometry benchmark run on this.

``surroundings`` (a :class:`~lowerbase.firmware_model.truth.Surroundings`, e.g. the world's
footprint contact) is what the robot can bump into; None (the default): open floor.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any, TypeVar

from lowerbase.clock import SimClock
from lowerbase.driver.core import DriverConfig, DriverCore
from lowerbase.firmware_model.faults import Fault
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import Profile, load_profile
from lowerbase.firmware_model.truth import Surroundings

FrameTap = Callable[[float, str, int, bytes], None]


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

    def run(self: L, seconds: float, on_step: Callable[[L], None] | None = None) -> None:
        for _ in range(round(seconds / self.control_dt)):
            self.step()
            if on_step is not None:
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
        for k in range(round(seconds / self.control_dt)):
            if k % every == 0:
                self.twist_driver.set_twist(linear, angular, smoothed)
            self.step()
            if on_step is not None:
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
        self.driver = DriverCore(self._from_driver, self.clock, driver_config)
        self.control_dt = self.mcu.dt
        self.twist_driver = self.driver
        self.mcu.truth.surroundings = surroundings

    @property
    def surroundings(self) -> Surroundings | None:
        """What the robot can collide with (asked by the ground-truth integrator each step)."""
        return self.mcu.truth.surroundings

    @surroundings.setter
    def surroundings(self, value: Surroundings | None) -> None:
        self.mcu.truth.surroundings = value

    def _from_mcu(self, frame_id: int, data: bytes) -> None:
        now = self.clock.now()
        self._to_driver.append((now, frame_id, data))
        if self.tap is not None:
            self.tap(now, "lower", frame_id, data)

    def _from_driver(self, frame_id: int, data: bytes) -> None:
        self._to_mcu.append((frame_id, data))
        if self.tap is not None:
            self.tap(self.clock.now(), "upper", frame_id, data)

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
