"""nav2's interface beside the vendor's (ROS 2 only: nav2_msgs has no ROS 1 package):
``navigate_to_pose`` (nav2_msgs/action/NavigateToPose) and ``compute_path_to_pose``
(nav2_msgs/action/ComputePathToPose), served by the navigation node's own navigator and
planner, the ones /move_base and make_plan use (:class:`Nav2Servers`).

- navigate_to_pose: the goal pose (in the map frame) goes to the navigator as a /move_base
  goal with no path poses does (:meth:`~lowerbase.navigation.actions.ActionServers.drive`);
  it preempts a /move_base goal and is preempted by one. Feedback every control tick:
  ``current_pose`` (the robot in the map frame), ``distance_remaining`` (the navigator's: along
  the plan from the robot), ``navigation_time`` (simulated or ROS time since the goal came),
  ``estimated_time_remaining`` (the distance at the controller's top speed),
  ``number_of_recoveries`` 0 (lowerbase's recoveries are not counted). The result is empty on
  success; on an abort ``error_code`` UNKNOWN (9000) with the reason in ``error_msg``. The
  behaviour tree is ignored.
- compute_path_to_pose: the global planner's path from ``start`` (``use_start``) or the robot's
  pose to ``goal`` (:meth:`~lowerbase.navigation.services.Services.plan`); ``error_code``
  NO_VALID_PATH (208) with the reason when there is none, UNKNOWN (200) for a refused goal or
  start. ``planner_id`` is ignored.
"""

from __future__ import annotations

import time
from typing import Any

from lowerbase.navigation.services import Services

#: [m/s] used for ``estimated_time_remaining`` when the limits give none
NOMINAL_SPEED = 0.5


def _duration(seconds: float) -> Any:
    from builtin_interfaces.msg import Duration

    ns = max(0, round(seconds * 1e9))
    return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


class Nav2Servers:
    """navigate_to_pose and compute_path_to_pose around one navigation node, whose face is
    advertised (its ``_servers`` are the vendor's action servers)."""

    def __init__(self, node: Any) -> None:
        from nav2_msgs.action import ComputePathToPose, NavigateToPose

        self.node = node
        self.NavigateToPose, self.ComputePathToPose = NavigateToPose, ComputePathToPose
        wire = node.wire
        self.navigate = wire.action_server("/navigate_to_pose", NavigateToPose,
                                           self._navigate, auto_start=False)
        self.compute = wire.action_server("/compute_path_to_pose", ComputePathToPose,
                                          self._compute, auto_start=False)
        self.services = Services(node)

    def start(self) -> None:
        self.navigate.start()
        self.compute.start()

    def shutdown(self) -> None:
        for server in (self.navigate, self.compute):
            if server.is_active():
                server.set_aborted(text="the navigation node is shutting down")

    def _navigate(self, goal: Any) -> None:
        from lowerbase.errors import LowerbaseError

        node, io, server = self.node, self.node.io, self.navigate
        action = self.NavigateToPose
        frame = node.setup.map_frame
        began = node.now()
        speed = float(node.limits.max_linear or NOMINAL_SPEED)

        def result(state: str) -> Any:
            return action.Result(error_code=0 if state == "succeeded"
                                 else action.Result.UNKNOWN)

        def feedback(pose: tuple[float, float, float]) -> None:
            with node.lock:
                left = float(node.navigator.distance_remaining)
            server.publish_feedback(action.Feedback(
                current_pose=io.pose_stamped(pose, node.rospy.Time.now(), frame),
                navigation_time=_duration(node.now() - began),
                estimated_time_remaining=_duration(left / speed),
                number_of_recoveries=0, distance_remaining=float(left)))

        try:
            target = io.stamped_pose(goal.pose, "navigate_to_pose pose", (frame,))
        except LowerbaseError as exc:
            server.set_aborted(result("aborted"), text=str(exc))
            return
        node._servers.drive(server, "navigate_to_pose", target, [], 0, feedback, result)

    def _compute(self, goal: Any) -> None:
        action = self.ComputePathToPose
        began = time.monotonic()
        start = goal.start if goal.use_start else None
        path, reason, refused = self.services.plan(goal.goal, start, 0.0,
                                                   "compute_path_to_pose")
        code = action.Result.NONE
        if reason:
            code = action.Result.UNKNOWN if refused else action.Result.NO_VALID_PATH
        out = action.Result(path=path, planning_time=_duration(time.monotonic() - began),
                            error_code=code, error_msg=reason)
        if code == action.Result.NONE:
            self.compute.set_succeeded(out, text="path found")
        else:
            self.compute.set_aborted(out, text=reason)
