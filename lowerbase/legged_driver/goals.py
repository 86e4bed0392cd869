"""Locomotion goals (``~walk`` / ``~stand`` / ``~sit``), ROS-free: the path along the state
table (:func:`next_request`) and its pursuit (:class:`GoalPursuit`), shared by the rospy node
(:mod:`lowerbase.legged_driver.node`) and the simulated loop (:mod:`lowerbase.simloop.legged`)."""

from __future__ import annotations

from collections import deque

from lowerbase.legged.body import ALLOWED
from lowerbase.legged_driver.core import LeggedDriverCore
from lowerbase.protocol.legged import LocomotionState

S = LocomotionState


def next_request(state: LocomotionState, goal: LocomotionState) -> LocomotionState | None:
    """The request that moves ``state`` one step toward ``goal`` along :data:`ALLOWED`, or None
    when there is nothing to send (reached, or waiting for an automatic step: commutation,
    sitting down). Never through MOTOR_DISABLED or COMM_DISABLED unless that is the goal, so a
    standing robot is not dropped on its way. SITDOWN_MODE counts as reached once seated
    (MOTOR_ENABLED) or when the robot is not up at all."""
    if goal == S.SITDOWN_MODE and state not in (S.STANDING_MODE, S.IN_CONTROL):
        return None
    if state == goal or state in (S.MOTOR_COMMUTATION, S.SITDOWN_MODE):
        return None
    avoid = {S.MOTOR_DISABLED, S.COMM_DISABLED} - {goal}
    edges = {s: set(ts) - avoid for s, ts in ALLOWED.items()}
    first: dict[LocomotionState, LocomotionState] = {t: t for t in edges[state]}
    queue = deque(edges[state])
    while queue:
        s = queue.popleft()
        if s == goal:
            return first[s]
        for t in edges[s]:
            if t not in first and t != state:
                first[t] = first[s]
                queue.append(t)
    return None


class GoalPursuit:
    """One locomotion goal: :meth:`pursue` sends the next LocomotionRequest toward it on a
    state change or every ``request_retry`` [s] (the core's clock) until the state moves, and
    drops it once reached or when a fault is latched."""

    def __init__(self, request_retry: float = 0.25) -> None:
        self.request_retry = request_retry
        self.goal: LocomotionState | None = None
        self.dropped = 0  #: goals dropped because a fault was latched
        self._sent: tuple[LocomotionState, float] | None = None  # (request, when)

    def set(self, goal: LocomotionState) -> None:
        self.goal, self._sent = goal, None

    def pursue(self, core: LeggedDriverCore) -> LocomotionState | None:
        """One step of the pursuit; returns the goal it dropped for a latched fault (the
        caller logs it), else None."""
        goal = self.goal
        if goal is None or not core.link_up:
            return None
        if core.fault:
            self.goal = None
            self.dropped += 1
            return goal
        want = next_request(core.state, goal)
        if want is None:
            if core.state == goal or (goal == S.SITDOWN_MODE and core.state in (
                    S.MOTOR_ENABLED, S.SITDOWN_MODE)):
                self.goal = None
            return None
        now = core.clock.now()
        sent = self._sent
        # (a tolerance of 1 ns: on the simulated clock, a sum of periods lands a hair short)
        if sent is None or sent[0] != want or now - sent[1] >= self.request_retry - 1e-9:
            core.request_state(want)
            self._sent = (want, now)
        return None
