"""The legged robot on one simulated clock: the lower computer and the legged driver core back
to back, as :class:`~lowerbase.simloop.loop.SimLoop` is for the wheeled chassis.

Every 1 ms (the lower computer's period, :data:`lowerbase.legged.lower.DT`) the lower
computer steps and its frames go straight to :class:`~lowerbase.legged_driver.core.
LeggedDriverCore` on the same leg bus (the 24 actuator frames of a period as one batch,
``on_frames``; the body frames one by one, ``on_frame``); every ``1 / command_rate`` the driver
ticks (BodyVelocityCommand) and a locomotion goal (``~walk`` / ``~stand`` / ``~sit``) is
pursued as the rospy node does it, by the same :class:`lowerbase.legged_driver.goals.
GoalPursuit` (retried every ``request_retry``). The driver's frames reach the lower computer
at once. Nothing is lost or reordered; ``tap(t, direction, bus, frame_id, data)`` sees every frame.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.bms.device import BmsDevice
from lowerbase.bms.pack import BatteryPack
from lowerbase.clock import SimClock
from lowerbase.legged.lower import LeggedLower
from lowerbase.legged.profile import LeggedProfile
from lowerbase.legged_driver.core import LeggedDriverConfig, LeggedDriverCore
from lowerbase.legged_driver.goals import GoalPursuit
from lowerbase.protocol.legged import LocomotionState

#: (t [s], "lower"|"upper", bus, frame id, data)
LeggedTap = Callable[[float, str, int, int, bytes], None]


class LeggedSimLoop:
    """The lower computer (with its pack) and the driver core on one :class:`SimClock`."""

    def __init__(self, profile: LeggedProfile | None = None, *, soc: float = 80.0,
                 config: LeggedDriverConfig | None = None, bms: bool = True,
                 request_retry: float = 0.25, tap: LeggedTap | None = None) -> None:
        self.profile = profile or LeggedProfile()
        self.clock = SimClock()
        self.tap = tap
        adapter = None
        if bms:
            p = self.profile
            adapter = McuBmsAdapter(BmsDevice(BatteryPack(p.battery, soc=soc)),
                                    low_soc=p.power.low_battery_soc,
                                    critical_soc=p.power.critical_battery_soc,
                                    temp_warning_c=p.power.battery_temp_warning)
        self.lower = LeggedLower(self.profile, self.clock, self._from_lower, bms=adapter,
                                 send_batch=self._batch_from_lower)
        self.driver = LeggedDriverCore(self._from_driver, self.clock, config)
        self.dt = self.lower.dt
        self.tick_every = max(1, round(1.0 / (self.driver.config.command_rate * self.dt)))
        self.goals = GoalPursuit(request_retry)
        self.steps = 0

    @property
    def now(self) -> float:
        return self.clock.now()

    def _from_lower(self, bus: int, frame_id: int, data: bytes) -> None:
        if self.tap is not None:
            self.tap(self.clock.now(), "lower", bus, frame_id, data)
        self.driver.on_frame(bus, frame_id, data)

    def _batch_from_lower(self, buses: np.ndarray, frame_ids: np.ndarray,
                          data: np.ndarray) -> None:
        if self.tap is not None:
            now, tap = self.clock.now(), self.tap
            for bus, frame_id, row in zip(buses.tolist(), frame_ids.tolist(), data,
                                          strict=True):
                tap(now, "lower", bus, frame_id, row.tobytes())
        self.driver.on_frames(buses, frame_ids, data)

    def _from_driver(self, bus: int, frame_id: int, data: bytes) -> None:
        if self.tap is not None:
            self.tap(self.clock.now(), "upper", bus, frame_id, data)
        self.lower.receive(bus, frame_id, data)

    @property
    def goal(self) -> LocomotionState | None:
        """The locomotion goal being pursued (None: none, or reached, or dropped)."""
        return self.goals.goal

    @property
    def goals_dropped(self) -> int:
        """Goals dropped because a fault was latched."""
        return self.goals.dropped

    def set_goal(self, goal: LocomotionState) -> None:
        """``~walk`` (IN_CONTROL), ``~stand`` (STANDING_MODE) or ``~sit`` (SITDOWN_MODE)."""
        self.goals.set(goal)

    def pursue_goal(self) -> None:
        """The node's pursue_goal on the simulated clock (:class:`GoalPursuit`)."""
        self.goals.pursue(self.driver)

    def step(self) -> None:
        """One 1 ms period: the driver's tick when due, the lower computer, the clock."""
        if self.steps % self.tick_every == 0:
            self.pursue_goal()
            self.driver.tick()
        self.lower.step()
        self.steps += 1
        self.clock.advance(self.dt)

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / self.dt)):
            self.step()

    def close(self) -> None:
        self.lower.shutdown()
