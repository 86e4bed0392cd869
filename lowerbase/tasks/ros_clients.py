"""The task machine's navigation and step moves over actionlib (imports rospy and actionlib).

Only :mod:`lowerbase.tasks.node` imports this, after checking that ROS is there.

- :class:`ActionNavigation`: the machine's ``Navigation`` as a SimpleActionClient of /move_base
  (woosh_msgs/MoveBaseAction, served by ``lowerbase navigation``). Its ``tick`` reports the
  goal's actionlib state as the navigator's (PENDING, ACTIVE, SUCCEEDED, ABORTED, PREEMPTED) and
  the status text as the reason; an ACTIVE goal whose text is ``path blocked: <reason>`` (the
  navigation node's :data:`~lowerbase.navigation.actions.BLOCKED_TEXT`) is the navigator's
  BLOCKED with that reason, as in TaskSim. The twist is always zero: the navigation node drives.
- :class:`ActionSteps`: the machine's step moves (docking) as a SimpleActionClient of
  /cmd_vel_control (woosh_msgs/StepControlAction). A PAUSE or RESUM goal supersedes the EXCUTE
  goal on the server and carries the list's result, so the client follows the latest goal only.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import actionlib  # type: ignore[import-untyped]
import rospy
from actionlib_msgs.msg import GoalStatus  # type: ignore[import-untyped]
from woosh_msgs.msg import (
    MoveBaseAction,
    MoveBaseGoal,
    StepControl,
    StepControlAction,
    StepControlGoal,
)

from lowerbase.errors import LowerbaseError
from lowerbase.navigation.actions import BLOCKED_TEXT
from lowerbase.navigation.ros_msgs import pose_stamped
from lowerbase.navigation.steps import (
    CANCEL,
    CANCELLED,
    EXCUTE,
    FAILED,
    PAUSE,
    REJECTED,
    RESUM,
    Step,
    StepController,
    StepResult,
)

log = logging.getLogger(__name__)
Pose = tuple[float, float, float]

#: actionlib GoalStatus -> the navigator's GoalState name
_NAV_STATE = {GoalStatus.PENDING: "PENDING", GoalStatus.ACTIVE: "ACTIVE",
              GoalStatus.PREEMPTING: "ACTIVE", GoalStatus.RECALLING: "PENDING",
              GoalStatus.SUCCEEDED: "SUCCEEDED", GoalStatus.ABORTED: "ABORTED",
              GoalStatus.REJECTED: "ABORTED", GoalStatus.PREEMPTED: "PREEMPTED",
              GoalStatus.RECALLED: "PREEMPTED", GoalStatus.LOST: "ABORTED"}
_DONE = (GoalStatus.SUCCEEDED, GoalStatus.ABORTED, GoalStatus.REJECTED, GoalStatus.PREEMPTED,
         GoalStatus.RECALLED, GoalStatus.LOST)


@dataclass(frozen=True)
class ActionFeedback:
    """A NavFeedback from the /move_base client (``state`` is a GoalState name)."""

    linear: float
    angular: float
    state: str
    status: str
    reason: str


class ActionNavigation:
    """The machine's Navigation over /move_base (see the module docstring)."""

    def __init__(self, name: str = "move_base", frame: str = "map") -> None:
        self.frame = frame
        self.client = actionlib.SimpleActionClient(name, MoveBaseAction)
        self.goals = 0
        self._cancelled = False

    def connected(self) -> bool:
        return bool(self.client.wait_for_server(rospy.Duration(0.01)))

    def send_goal(self, target: Pose, poses: Sequence[Pose] = (), execution_mode: int = 0,
                  now: float = 0.0) -> None:
        if not self.connected():
            raise LowerbaseError("no /move_base action server: start lowerbase navigation")
        stamp = rospy.Time.now()
        goal = MoveBaseGoal(target_pose=pose_stamped(target, stamp, self.frame),
                            poses=[pose_stamped(p, stamp, self.frame) for p in poses],
                            execution_mode=int(execution_mode))
        self.client.send_goal(goal)
        self.goals += 1
        self._cancelled = False

    def cancel(self, now: float) -> None:
        if self.goals and not self._cancelled:
            self.client.cancel_goal()
            self._cancelled = True

    def tick(self, now: float, pose: Pose) -> ActionFeedback:
        if not self.goals:
            return ActionFeedback(0.0, 0.0, "PENDING", "no goal", "")
        state = self.client.get_state()
        text = self.client.get_goal_status_text() or ""
        name = _NAV_STATE.get(state, "ACTIVE")
        if state == GoalStatus.LOST and not text:
            text = "the /move_base goal was lost (is lowerbase navigation running?)"
        if name == "ACTIVE" and text.startswith(BLOCKED_TEXT):
            return ActionFeedback(0.0, 0.0, name, "BLOCKED", text[len(BLOCKED_TEXT):])
        return ActionFeedback(0.0, 0.0, name, _state_name(state), text)


#: polls (20 Hz) to wait for a done goal's result message before taking it as lost
RESULT_WAITS = 40


class ActionSteps:
    """The machine's step moves over /cmd_vel_control (see the module docstring)."""

    def __init__(self, name: str = "cmd_vel_control") -> None:
        self.client = actionlib.SimpleActionClient(name, StepControlAction)
        self.steps: list[Step] = []
        self.result: StepResult | None = None
        self._check = StepController()
        self._sent = False
        self._result_waits = 0  #: polls that saw the goal done but no result message yet

    @property
    def active(self) -> bool:
        return bool(self.steps) and self.result is None

    def _send(self, mode: int, steps: Sequence[Step] = (), use_avoid: bool = False) -> None:
        goal = StepControlGoal(mode=mode, useAvoid=use_avoid, stepControl=[
            StepControl(executeMode=s.execute_mode, data=s.data, speed=s.speed, angle=s.angle)
            for s in steps])
        self.client.send_goal(goal)
        self._sent, self._result_waits = True, 0

    def goal(self, mode: int, steps: Sequence[Step] = (), use_avoid: bool = False
             ) -> StepResult | None:
        """As StepController.goal: EXCUTE refused at once when the list cannot run (the same
        check as the server's), else sent; PAUSE/RESUM/CANCEL sent while a list runs."""
        if mode == EXCUTE:
            why = self._check.check(steps)
            if why:
                return StepResult(REJECTED, steps[0].execute_mode if steps else 0, 0.0, why)
            if not self.client.wait_for_server(rospy.Duration(0.01)):
                return StepResult(REJECTED, 0, 0.0, "no /cmd_vel_control action server: "
                                  "start lowerbase navigation")
            self.steps, self.result = list(steps), None
            self._send(EXCUTE, steps, use_avoid)
            return None
        self._poll()
        if not self.active:
            return None
        if mode in (PAUSE, RESUM):
            self._send(mode)
        elif mode == CANCEL:
            self._send(CANCEL)
            self.result = StepResult(CANCELLED, 0, 0.0, "cancelled")
        return None

    def _poll(self) -> None:
        if not self._sent or self.result is not None or not self.steps:
            return
        state = self.client.get_state()
        if state not in _DONE:
            return
        res = self.client.get_result()
        if res is None and self._result_waits < RESULT_WAITS:
            # the goal's status topic can show it done before its result message arrived
            self._result_waits += 1
            return
        text = self.client.get_goal_status_text() or _state_name(state)
        if state == GoalStatus.SUCCEEDED and res is not None:
            self.result = StepResult(int(res.result), int(res.executeMode), float(res.percent),
                                     text)
        elif state == GoalStatus.PREEMPTED and res is not None and res.result == CANCELLED:
            self.result = StepResult(CANCELLED, int(res.executeMode), float(res.percent), text)
        elif state == GoalStatus.ABORTED and res is not None and res.result == FAILED:
            # the list ran but a step stayed off (lowerbase navigation aborts with FAILED)
            self.result = StepResult(FAILED, int(res.executeMode), float(res.percent), text)
        else:
            self.result = StepResult(REJECTED, 0, 0.0, text or "the step list failed")

    def tick(self, odom: Sequence[float]) -> None:
        """Follow the latest goal; no twist: the navigation node drives the steps."""
        self._poll()


def _state_name(state: int) -> str:
    return str(actionlib.get_name_of_constant(GoalStatus, state))
