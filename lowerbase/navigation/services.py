"""The navigation node's services: /move_base/make_plan (nav_msgs/GetPlan),
/move_base/enable_costmaps (std_srvs/SetBool) and /move_base/clear_costmaps (std_srvs/Empty).

Each answers from the :class:`~lowerbase.navigation.node.NavigationNode`'s Navigator under the
node's lock; bad input (a NaN pose, a pose off the map, another frame, no robot pose yet) is an
empty plan with the reason in one log line, never an exception out of rospy's service thread.
"""

from __future__ import annotations

import logging
from typing import Any

from lowerbase.errors import LowerbaseError, WorldError
from lowerbase.text import point

log = logging.getLogger(__name__)


class Services:
    """The service handlers of one node (rospy.Service callbacks)."""

    def __init__(self, node: Any) -> None:
        self.node = node

    def make_plan(self, req: Any) -> Any:
        """nav_msgs/GetPlan; an empty path when there is none (the reason goes to the log: the
        response has no message field). An empty start frame means the robot's pose."""
        from nav_msgs.srv import GetPlanResponse

        start = None if req.start.header.frame_id == "" else req.start
        path, _reason, _refused = self.plan(req.goal, start, float(req.tolerance), "make_plan")
        return GetPlanResponse(plan=path)

    def plan(self, goal_msg: Any, start_msg: Any, tolerance: float,
             what: str) -> tuple[Any, str, bool]:
        """The global planner's path (nav_msgs/Path, published on the plan topic) from
        ``start_msg`` (a PoseStamped; None: the robot's pose) to ``goal_msg``, and why it is
        empty ("" when it is not), and whether the goal or the start was refused. Shared
        by make_plan and nav2's compute_path_to_pose."""
        node = self.node
        io, frame = node.io, node.setup.map_frame
        stamp = node.rospy.Time.now()
        try:
            goal = io.stamped_pose(goal_msg, f"{what} goal", (frame,))
            if start_msg is None:
                start = node.map_pose()
                if start is None:
                    raise WorldError(f"{what}: the start has no frame_id and the robot's "
                                     "pose is unknown (no /odom or map -> odom yet)")
            else:
                start = io.stamped_pose(start_msg, f"{what} start", (frame,))
            with node.lock:  # the check and a copy of the costs; the search without it
                job = node.navigator.plan_job(start, goal, tolerance)
            plan = job()
        except LowerbaseError as exc:
            log.warning("%s refused: %s", what, exc)
            return io.path_msg([], stamp, frame), str(exc), True
        if not plan.ok:
            log.warning("%s: no path from %s to %s: %s", what, point(start[0], start[1]),
                        point(goal[0], goal[1]), plan.reason)
        path = io.path_msg(plan.poses, stamp, frame)
        node.stats["plans"] += 1
        node.pubs["plan"].publish(path)
        return path, "" if plan.ok else (plan.reason or "no path"), False

    def enable(self, req: Any) -> Any:
        from std_srvs.srv import SetBoolResponse  # type: ignore[import-untyped]

        node = self.node
        with node.lock:
            answers = [getattr(node.navigator, f"{w}_costmap").enable(bool(req.data))
                       for w in ("global", "local")]
            node.navigator.combined.refresh()
        ok = all(a[0] for a in answers)
        return SetBoolResponse(success=ok, message=answers[1][1])

    def clear(self, req: Any) -> Any:
        from std_srvs.srv import EmptyResponse

        node = self.node
        with node.lock:
            node.navigator.clear_costmaps()
        log.info("costmaps cleared")
        return EmptyResponse()
