"""The legged robot on one simulated clock: the lower computer and the legged driver core back
to back, as :class:`~lowerbase.simloop.loop.SimLoop` is for the wheeled chassis.

Every 1 ms (the lower computer's period, :data:`lowerbase.legged.lower.DT`) the lower
computer steps and its frames go straight to :class:`~lowerbase.legged_driver.core.
LeggedDriverCore` (``on_frame``) on the same leg bus; every ``1 / command_rate`` the driver
ticks (BodyVelocityCommand) and a locomotion goal is pursued as the rospy node does it
(``~walk`` / ``~stand`` / ``~sit``: :func:`lowerbase.legged_driver.node.next_request`, retried every
``request_retry``). The driver's frames reach the lower computer at once. Nothing is lost or
reordered; ``tap(t, direction, bus, frame_id, data)`` sees every frame.
"""

from __future__ import annotations

from collections.abc import Callable

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.bms.device import BmsDevice
from lowerbase.bms.pack import BatteryPack
from lowerbase.clock import SimClock
from lowerbase.legged.lower import LeggedLower
from lowerbase.legged.profile import LeggedProfile
from lowerbase.legged_driver.core import LeggedDriverConfig, LeggedDriverCore
from lowerbase.legged_driver.node import next_request
from lowerbase.protocol.legged import LocomotionState

S = LocomotionState
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
        self.lower = LeggedLower(self.profile, self.clock, self._from_lower, bms=adapter)
        self.driver = LeggedDriverCore(self._from_driver, self.clock, config)
        self.dt = self.lower.dt
        self.tick_every = max(1, round(1.0 / (self.driver.config.command_rate * self.dt)))
        self.request_retry = request_retry
        self.goal: LocomotionState | None = None
        self.goals_dropped = 0  #: goals dropped because a fault was latched
        self._goal_sent: tuple[LocomotionState, float] | None = None
        self.steps = 0

    @property
    def now(self) -> float:
        return self.clock.now()

    def _from_lower(self, bus: int, frame_id: int, data: bytes) -> None:
        if self.tap is not None:
            self.tap(self.clock.now(), "lower", bus, frame_id, data)
        self.driver.on_frame(bus, frame_id, data)

    def _from_driver(self, bus: int, frame_id: int, data: bytes) -> None:
        if self.tap is not None:
            self.tap(self.clock.now(), "upper", bus, frame_id, data)
        self.lower.receive(bus, frame_id, data)

    def set_goal(self, goal: LocomotionState) -> None:
        """``~walk`` (IN_CONTROL), ``~stand`` (STANDING_MODE) or ``~sit`` (SITDOWN_MODE)."""
        self.goal, self._goal_sent = goal, None

    def pursue_goal(self) -> None:
        """The node's pursue_goal on the simulated clock: the next request along the state
        table, again every ``request_retry`` until the state moves; dropped when reached or
        when a fault is latched."""
        goal, core = self.goal, self.driver
        if goal is None or not core.link_up:
            return
        if core.fault:
            self.goal = None
            self.goals_dropped += 1
            return
        want = next_request(core.state, goal)
        if want is None:
            if core.state == goal or (goal == S.SITDOWN_MODE and core.state in (
                    S.MOTOR_ENABLED, S.SITDOWN_MODE)):
                self.goal = None
            return
        now = self.clock.now()
        sent = self._goal_sent
        if sent is None or sent[0] != want or now - sent[1] >= self.request_retry - 1e-9:
            core.request_state(want)
            self._goal_sent = (want, now)

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
