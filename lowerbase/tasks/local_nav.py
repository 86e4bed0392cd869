"""The task machine's navigation on a navigation node in the same process (the lockstep
robot, :mod:`lowerbase.robot.lockstep`): what :mod:`lowerbase.tasks.ros_clients` does over
/move_base and /cmd_vel_control, done as those action servers do it, under the node's lock, so
that nothing waits for a message.

- :class:`NodeNavigation`: goals to the node's Navigator (a running step list is cancelled, as
  the /move_base server does); ``tick`` reports the navigator's state and the node's last
  command.
- :class:`NodeSteps`: step lists to the node's StepController (a running move_base goal is
  cancelled, as the /cmd_vel_control server does); the node's control tick drives them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from lowerbase.navigation.controller import Status as CtrlStatus
from lowerbase.navigation.navigator import GoalState, NavCommand
from lowerbase.navigation.steps import CANCEL, CANCELLED, EXCUTE, Step, StepResult

Pose = tuple[float, float, float]


class NodeNavigation:
    """The machine's Navigation on a NavigationNode of this process."""

    def __init__(self, node: Any) -> None:
        self.node = node

    def send_goal(self, target: Pose, poses: Sequence[Pose] = (), execution_mode: int = 0,
                  now: float = 0.0) -> None:
        node = self.node
        with node.lock:
            if node.steps.active:
                node.steps.goal(CANCEL)
            node.last_command = None
            node.navigator.send_goal(target, poses, execution_mode, now)

    def cancel(self, now: float) -> None:
        with self.node.lock:
            self.node.navigator.cancel(now)

    def tick(self, now: float, pose: Pose) -> NavCommand:
        node = self.node
        with node.lock:
            nav, last = node.navigator, node.last_command
            state = nav.state if nav.state is not None else GoalState.PENDING
            if last is None or state == GoalState.PENDING:
                return NavCommand(0.0, 0.0, state, CtrlStatus.IDLE, nav.reason)
            return NavCommand(last.linear, last.angular, state, last.status, nav.reason)


class NodeSteps:
    """The machine's step moves on a NavigationNode's StepController (the interface of
    :class:`lowerbase.tasks.ros_clients.ActionSteps`: ``steps`` is the list sent, ``result``
    how it ended)."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.steps: list[Step] = []
        self.result: StepResult | None = None

    @property
    def active(self) -> bool:
        return bool(self.steps) and self.result is None

    def goal(self, mode: int, steps: Sequence[Step] = (), use_avoid: bool = False
             ) -> StepResult | None:
        node = self.node
        with node.lock:
            ctrl = node.steps
            if mode == EXCUTE:
                refused = ctrl.goal(EXCUTE, steps, use_avoid)
                if refused is not None:
                    return refused
                self.steps, self.result = list(steps), None
                if node.navigator_active():
                    node.navigator.cancel(node.now())
                return None
            self._poll()
            if not self.active:
                return None
            ctrl.goal(mode)
            if mode == CANCEL:
                self.result = StepResult(CANCELLED, 0, 0.0, "cancelled")
            return None

    def _poll(self) -> None:
        if self.steps and self.result is None:
            self.result = self.node.steps.result

    def tick(self, odom: Sequence[float]) -> None:
        """Follow the list; no twist: the navigation node drives the steps."""
        with self.node.lock:
            self._poll()
