"""move_base without ROS: :class:`Navigator`, goals, replanning and navigation modes on the
simulated clock.

The caller (``lowerbase.navigation.sim.NavSim`` on a WorldSim, or the rospy layer) feeds it the
robot's map pose and sensor data and sends the twist it answers, at 20 Hz:

- :meth:`Navigator.update_sensors` marks and clears the local costmap (rolling window) from the
  merged /scan and the depth camera's cloud;
- :meth:`Navigator.tick` plans (on the global costmap with the local marks pasted in, see
  ``combined``), follows the plan with :class:`PathController`, and runs the goal's state machine
  (actionlib's: PENDING -> ACTIVE -> SUCCEEDED / ABORTED / PREEMPTED):

  * reached within ``xy_tolerance`` / ``yaw_tolerance`` (5 cm, 2 deg): SUCCEEDED;
  * BLOCKED by an obstacle: wait or replan around it as the navigation mode says (``modes``);
    no path: ABORTED; more than ``max_replans`` replans while blocked: ABORTED;
  * no progress (``progress_distance`` / ``progress_angle``) for ``stuck_timeout`` s while not
    waiting for an obstacle (an e-stop, a wheel fault, a robot pushed against something):
    ABORTED;
  * a new goal preempts the active one (PREEMPTED), so does :meth:`Navigator.cancel`.

``poses`` with a goal is a path to follow through: ``execution_mode`` 1 point by point (each pose
is reached within the tolerances, yaw included, and the robot stops there before the next),
0 free (one path planned between consecutive poses, driven through without stopping; only the
target is reached within the tolerances).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from lowerbase.navigation.combined import CombinedCosts
from lowerbase.navigation.controller import (
    ControllerConfig,
    Limits,
    PathController,
    Status,
    wrap,
)
from lowerbase.navigation.costmap import (
    LayeredCostmap,
    global_costmap,
    local_costmap,
)
from lowerbase.navigation.goals import (
    GoalResult,
    GoalState,
    NavCommand,
    NavigationError,
    NavigatorConfig,
    Pose,
    ProgressWatch,
    _pose,
    check_on_map,
    path_blocked,
    remaining,
)
from lowerbase.navigation.modes import Mode, NavigationModeGoal
from lowerbase.navigation.planner import (
    LETHAL,
    FootprintCells,
    Plan,
)
from lowerbase.navigation.planning import GoalPlanner, drive_reversed
from lowerbase.navigation.recovery import Recoveries
from lowerbase.world.footprint import DEFAULT_POINTS, Footprint
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import LaserScan

__all__ = ["GoalResult", "GoalState", "Mode", "NavCommand", "NavigationError",
           "NavigationModeGoal", "Navigator", "NavigatorConfig", "Pose"]


class Navigator:
    """move_base's core (see the module docstring)."""

    def __init__(self, grid: OccupancyGrid, config: NavigatorConfig | None = None,
                 limits: Limits | None = None,
                 footprint: Footprint | Sequence[tuple[float, float]] = DEFAULT_POINTS
                 ) -> None:
        self.config = cfg = config or NavigatorConfig()
        self.grid = grid
        fp = footprint if isinstance(footprint, Footprint) else Footprint(tuple(footprint))
        params = replace(cfg.costmap, footprint=fp)
        self.global_costmap: LayeredCostmap = global_costmap(grid, params)
        centre = (grid.origin[0] + grid.width * grid.resolution / 2,
                  grid.origin[1] + grid.height * grid.resolution / 2, 0.0)
        self.local_costmap: LayeredCostmap = local_costmap(
            grid, centre, replace(params, width=cfg.local_size, height=cfg.local_size,
                                  static_map=False, resolution=grid.resolution))
        self.combined = CombinedCosts(self.global_costmap, self.local_costmap)
        self.limits = limits or Limits()
        self.mode = NavigationModeGoal()
        self._footprints()
        self.controller = PathController(
            self.combined.costs, grid.resolution, self.combined.origin,
            footprint=[tuple(p) for p in self._fp_forward.points], limits=self.limits,
            config=self._controller_config())
        self.state: GoalState | None = None  #: None before the first goal
        self.goal_id = 0
        self.target: Pose | None = None
        self.results: list[GoalResult] = []  #: every goal that ended, oldest first
        self.reason = ""  #: the result's reason (or what the active goal waits for)
        self.feedback_pose: Pose | None = None
        self.distance_remaining = 0.0
        self.replans = 0  #: replans of the current goal because it was blocked
        self.early_replans = 0  #: replans because the local costmap blocked the path ahead
        self.planning = GoalPlanner(cfg, self.global_costmap, self.combined, grid.resolution)
        self.path: list[Pose] = []  #: the plan being followed (map frame)
        self._recovery = Recoveries(self.config.back_off,
                                    behaviors=self.config.recovery_behaviors)
        self._reset_goal_state()

    @property
    def plans(self) -> int:
        """Plans made for goals."""
        return self.planning.plans

    # -- setup -----------------------------------------------------------------------------------
    def _footprints(self) -> None:
        pts = [(float(x), float(y)) for x, y in self.global_costmap.padded.points]
        res = self.grid.resolution
        self._fp_forward = FootprintCells(pts, res)
        self._fp_reverse = FootprintCells([(-x, -y) for x, y in pts], res)
        # the robot itself, without footprint_padding: what a recovery move keeps off lethal
        # cells (the padding is the planner's margin; a StepControl move has none either)
        body = [(float(x), float(y)) for x, y in self.global_costmap.footprint.points]
        self._fp_body = FootprintCells(body, res)

    def _controller_config(self) -> ControllerConfig:
        cfg = self.config
        speed = self.mode.max_speed if self.mode.max_speed > 0 else cfg.default_max_speed
        speed = min(speed, self.limits.max_linear)
        return replace(cfg.controller, max_speed=max(speed, 1e-3),
                       xy_tolerance=cfg.xy_tolerance, yaw_tolerance=cfg.yaw_tolerance)

    def _reset_goal_state(self) -> None:
        self._waypoints: list[Pose] = []
        self._point_by_point = False
        self._leg_ends: list[int] = []  # free mode: path index where each waypoint is
        self._need_plan = False
        self._blocked_since: float | None = None
        self._blind_since: float | None = None  # sensing out of date since
        self._progress = ProgressWatch(self.config.progress_distance,
                                       self.config.progress_angle, self.config.stuck_timeout)
        self._last_early = -math.inf
        self._seen_version = -1
        self._reverse = False
        if hasattr(self, "_recovery"):
            self._recovery.cancel()

    def set_limits(self, limits: Limits) -> None:
        """maxLinear/maxAngular and the acceleration limits (driver_base's /parameter)."""
        self.limits = limits
        self.controller.limits = limits
        self.controller.config = self._controller_config()

    def set_mode(self, goal: NavigationModeGoal) -> tuple[bool, str]:
        """/navigation_mode: (accepted, message). A refused goal changes nothing."""
        why = goal.check()
        if why:
            return False, f"navigation mode refused: {why}"
        self.mode = goal
        self.controller.config = self._controller_config()
        note = ""
        if goal.navigation_mode == Mode.WAIT_THEN_AVOID and goal.waiting_timeout < 0:
            note = " (waiting_timeout < 0 in mode 3: precise avoidance)"
        return True, f"navigation mode {goal.effective_mode.name.lower()}{note}"

    def set_footprint(self, points: Sequence[Sequence[float]], which: str = "both") -> None:
        """A new footprint (x, y[, z] in base_link) for ``which`` costmap, as the
        /move_base/{global,local}_costmap/set_footprint topics: "global" also changes the
        footprint the planner and the controller check; "local" only the local costmap's
        inflation and footprint clearing; "both" all of it. A bad polygon raises one
        WorldError line, an unknown ``which`` a NavigationError; nothing changes then."""
        if which not in ("global", "local", "both"):
            raise NavigationError(f"set_footprint: which = {which!r}; one of 'global', "
                                  "'local', 'both'")
        if which in ("global", "both"):
            self.global_costmap.set_footprint(points)
            self.combined.invalidate_static()
            self._footprints()
            self.controller.footprint = self._fp_reverse if self._reverse else self._fp_forward
        if which in ("local", "both"):
            self.local_costmap.set_footprint(points)
        self.combined.refresh()

    # -- sensors and plans -----------------------------------------------------------------------
    def update_sensors(self, pose: Sequence[float], scan: LaserScan | None = None,
                       cloud: tuple[np.ndarray, Sequence[float]] | None = None) -> None:
        """Mark and clear the local costmap at the robot's map ``pose`` (see
        :meth:`LayeredCostmap.update`)."""
        self.update_observations([(pose, scan, cloud)])

    def update_observations(self, items: Sequence[tuple[Sequence[float], LaserScan | None,
                                                        tuple[np.ndarray, Sequence[float]] | None]]
                            ) -> None:
        """Several updates, each (pose, scan, cloud) at its own pose (the ROS node: each
        observation at the pose of its stamp); the combined costs are rebuilt once."""
        for pose, scan, cloud in items:
            self.local_costmap.update(pose, scan=scan, cloud=cloud)
        if items:
            self.combined.refresh()

    def clear_costmaps(self) -> None:
        """/move_base/clear_costmaps."""
        self.global_costmap.clear()
        self.local_costmap.clear()
        self.combined.refresh()

    def make_plan(self, start: Sequence[float], goal: Sequence[float],
                  tolerance: float = 0.0) -> Plan:
        """/move_base/make_plan (nav_msgs/GetPlan): a plan on the global costmap with the local
        marks and the mode's clearance; empty with a reason when there is none. A start inside
        an obstacle's inflation is planned out of (the robot may be there after localization
        error); a NaN pose or bad tolerance: :class:`PlanningError`; a start off the map, or a
        goal off it by more than ``tolerance``: :class:`NavigationError`."""
        return self.plan_job(start, goal, tolerance)()

    def plan_job(self, start: Sequence[float], goal: Sequence[float],
                 tolerance: float = 0.0) -> Callable[[], Plan]:
        """:meth:`make_plan` in two halves (the ROS service's): this one checks the request
        and copies the costs, under the node's lock; the returned call plans on the copy
        outside it, so a long search never stalls the control loop. Errors as make_plan's."""
        s, g = _pose(start, "start"), _pose(goal, "goal")
        check_on_map(self.grid.extent, s[0], s[1], "start")
        if math.isfinite(tolerance):
            check_on_map(self.grid.extent, g[0], g[1], "goal", max(tolerance, 0.0))
        return self.planning.plan_job(s, g, tolerance, self.mode, self._fp_forward)

    # -- goals -----------------------------------------------------------------------------------
    def send_goal(self, target: Sequence[float], poses: Sequence[Sequence[float]] = (),
                  execution_mode: int = 0, now: float = 0.0) -> None:
        """/move_base: a new goal (map frame). ``poses``: a path to follow to the target
        (``execution_mode`` 1 point by point, 0 free). An active goal is PREEMPTED. A NaN or
        off-map pose, or an unknown execution_mode: :class:`NavigationError`, nothing changed."""
        points = [_pose(p, f"path pose {i}") for i, p in enumerate(poses)]
        points.append(_pose(target, "target pose"))
        for x, y, _ in points:
            check_on_map(self.grid.extent, x, y, "goal")
        if execution_mode not in (0, 1):
            raise NavigationError(f"execution_mode {execution_mode!r} is not known; 1 point by "
                                  f"point, 0 free")
        if self.state in (GoalState.PENDING, GoalState.ACTIVE):
            self._finish(GoalState.PREEMPTED, "preempted by a new goal", now)
        self._reset_goal_state()
        self.goal_id += 1
        self.target = points[-1]
        self._waypoints = points
        self._point_by_point = execution_mode == 1
        self._need_plan = True
        self.replans = self.early_replans = 0
        self.state = GoalState.PENDING
        self.reason = ""

    def cancel(self, now: float) -> None:
        """Cancel the active goal (PREEMPTED); the next commands are zero."""
        if self.state in (GoalState.PENDING, GoalState.ACTIVE):
            self._finish(GoalState.PREEMPTED, "cancelled", now)

    def _finish(self, state: GoalState, reason: str, now: float) -> NavCommand:
        self.state = state
        self.reason = reason
        self.results.append(GoalResult(self.goal_id, state, reason, now))
        self._recovery.cancel()
        self.controller.set_plan([])
        self.controller.v = self.controller.w = 0.0
        self.path = []
        return NavCommand(0.0, 0.0, state, Status.IDLE, reason)

    def _plan(self, pose: Pose) -> str:
        """Plan from ``pose`` through the remaining waypoints; '' or why there is no plan.
        With no plan while the local costmap holds marks, move_base's planner-failure
        recovery first: the local obstacle layer reset (marks made with a heading error, or
        of something gone, whose keep-out closes an aisle), then one more plan; the next scan
        marks what is really there."""
        why = self._plan_once(pose)
        if why and self.config.clear_on_no_path and self._recovery.clear_for_plan(
                self.local_costmap):
            self.combined.refresh()
            why = self._plan_once(pose)
        return why

    def _plan_once(self, pose: Pose) -> str:
        goals = self._waypoints[:1] if self._point_by_point else self._waypoints
        planned = self.planning.through(pose, goals, self.mode, self._fp_forward)
        if isinstance(planned, str):
            return planned
        poses, self._leg_ends = planned
        self.path = poses
        self._reverse = drive_reversed(self.mode.nav_dir, pose, poses)
        self.controller.footprint = self._fp_reverse if self._reverse else self._fp_forward
        self.controller.set_costmap(self.combined.costs, self.grid.resolution,
                                    self.combined.origin)
        if self._reverse:
            self.controller.set_plan([(x, y, wrap(a + math.pi)) for x, y, a in poses])
        else:
            self.controller.set_plan(poses)
        return ""

    def _passed_waypoints(self) -> int:
        """Free mode: how many waypoints the robot has passed on the current path."""
        index = self.controller._index
        return sum(1 for end in self._leg_ends[:-1] if end <= index)

    def _replan(self, pose: Pose, now: float) -> str:
        if not self._point_by_point:
            del self._waypoints[:self._passed_waypoints()]
        why = self._plan(pose)
        self._blocked_since = None
        self._progress.restart(now, pose)
        return why

    # -- the control step ------------------------------------------------------------------------
    def tick(self, now: float, pose: Sequence[float], sensed: float | None = None
             ) -> NavCommand:
        """One control step (20 Hz) at the robot's map ``pose``: the twist and the state.
        ``sensed``: the time [s] of the older of the newest scan and the newest localization
        (None: not known; not checked): older than ``sensing_timeout``, the robot stops and
        waits (Status.WAITING), ``sensing_patience`` long: ABORTED."""
        p = _pose(pose, "robot pose")
        self.feedback_pose = p
        if self.state not in (GoalState.PENDING, GoalState.ACTIVE):
            state = self.state or GoalState.PENDING
            return NavCommand(0.0, 0.0, state, Status.IDLE, self.reason)
        if sensed is not None and now - sensed > self.config.sensing_timeout:
            return self._blind(p, now, now - sensed)
        self._blind_since = None
        if self._need_plan:
            self._need_plan = False
            self.state = GoalState.ACTIVE
            why = self._plan(p)
            if why:
                return self._finish(GoalState.ABORTED, f"no path: {why}", now)
            self._progress.restart(now, p)
        if self._recovery.active:
            twist = self._recovery.step(p, now, self.combined.costs, self.combined.origin,
                                        self._fp_forward, self.local_costmap, self._fp_body)
            if twist is None and self._recovery.resense(p, now, self.local_costmap):
                self.combined.refresh()  # stale marks around the robot gone; re-sense
                twist = (0.0, 0.0)
            if twist is not None:
                self._progress.restart(now, p)  # recovering is not being stuck
                return NavCommand(*twist, GoalState.ACTIVE, Status.BLOCKED, self.reason)
            self.controller.v = self.controller.w = 0.0
            why = self._replan(p, now)
            if why:
                return self._finish(GoalState.ABORTED, f"no path around the obstacle: {why}",
                                    now)
        if self.combined.version != self._seen_version:
            self._seen_version = self.combined.version
            self.controller.set_costmap(self.combined.costs, self.grid.resolution,
                                        self.combined.origin)
            if self.mode.avoids_early and now - self._last_early >= self.config.replan_interval \
                    and self._path_ahead_blocked():
                self._last_early = now
                self.early_replans += 1
                if self.early_replans > self.config.max_early_replans:
                    return self._finish(GoalState.ABORTED, f"no way found: replanned "
                                        f"{self.config.max_early_replans} times as obstacles "
                                        f"came into view", now)
                why = self._replan(p, now)
                if why:
                    return self._finish(GoalState.ABORTED, f"no path around the obstacle: "
                                                           f"{why}", now)
        command = self._compute(p)
        self._update_remaining(p)
        if command.status is Status.SUCCEEDED:
            return self._reached(p, now)
        if command.status is Status.BLOCKED:
            return self._blocked(p, now, command)
        self._blocked_since = None
        self.reason = ""
        stuck = self._progress.stuck(now, p)
        if stuck:
            return self._finish(GoalState.ABORTED, stuck, now)
        return NavCommand(command.linear, command.angular, GoalState.ACTIVE, command.status)

    def _blind(self, p: Pose, now: float, age: float) -> NavCommand:
        """Sensing is out of date: never drive blind; wait, then give up."""
        if self._blind_since is None:
            self._blind_since = now
        if now - self._blind_since >= self.config.sensing_patience:
            return self._finish(GoalState.ABORTED, f"sensing stopped: no fresh scan or "
                                f"localization for {age:.1f} s", now)
        self.controller.v = self.controller.w = 0.0
        self._progress.restart(now, p)  # waiting for sensing is not being stuck
        return NavCommand(0.0, 0.0, self.state or GoalState.PENDING, Status.WAITING,
                          f"waiting for sensing: the newest scan or localization is "
                          f"{age:.1f} s old")

    def _compute(self, p: Pose) -> NavCommand:
        if self._reverse:
            cmd = self.controller.compute((p[0], p[1], wrap(p[2] + math.pi)))
            return NavCommand(-cmd.linear, cmd.angular, GoalState.ACTIVE, cmd.status, cmd.reason)
        cmd = self.controller.compute(p)
        return NavCommand(cmd.linear, cmd.angular, GoalState.ACTIVE, cmd.status, cmd.reason)

    def _reached(self, p: Pose, now: float) -> NavCommand:
        if self._point_by_point and len(self._waypoints) > 1:
            self._waypoints.pop(0)
            why = self._plan(p)
            if why:
                return self._finish(GoalState.ABORTED, f"no path: {why}", now)
            self._progress.restart(now, p)
            return NavCommand(0.0, 0.0, GoalState.ACTIVE, Status.SUCCEEDED,
                              "waypoint reached")
        return self._finish(GoalState.SUCCEEDED, "goal reached", now)

    def _blocked(self, p: Pose, now: float, command: NavCommand) -> NavCommand:
        if self._blocked_since is None:
            self._blocked_since = now
        self._progress.restart(now, p)  # waiting for an obstacle is not being stuck
        if now - self._blocked_since >= self.mode.avoids_after(self.config.blocked_patience):
            self.replans += 1
            if self.replans > self.config.max_replans:
                return self._finish(GoalState.ABORTED, f"blocked: still no way after "
                                                       f"{self.config.max_replans} replans", now)
            # wedged (the footprint on a lethal cell) or a replan that did not help: a
            # recovery first (recovery.ORDER), then the replan (in tick, after a move)
            here = self._fp_forward.max_cost(self.combined.costs, self.combined.origin, *p)[0]
            step = self._recovery.pick(self.replans, here >= LETHAL)
            if step:
                moving = self._recovery.begin(step, p, now, self._reverse, self.local_costmap)
                if moving:  # backing off or turning first
                    self._blocked_since = None
                    self.reason = moving
                    return NavCommand(0.0, 0.0, GoalState.ACTIVE, Status.BLOCKED, self.reason)
                self.combined.refresh()  # a costmap reset: at once, then the replan
            why = self._replan(p, now)
            if why:
                return self._finish(GoalState.ABORTED, f"no path around the obstacle: {why}",
                                    now)
        self.reason = "waiting: an obstacle blocks the path"
        return NavCommand(command.linear, command.angular, GoalState.ACTIVE, Status.BLOCKED,
                          self.reason)

    def _path_ahead_blocked(self) -> bool:
        """Whether the rest of the plan crosses an INSCRIBED or LETHAL cell now."""
        # the controller's array of the plan: its x and y are the plan's (reversed, only the
        # headings differ), without converting the list of poses every update
        return path_blocked(self.controller.path[self.controller._index:], self.combined.costs,
                            self.grid.resolution, self.combined.origin)

    def _update_remaining(self, p: Pose) -> None:
        self.distance_remaining = remaining(self.path, self.controller._index, p,
                                            self.controller.config.approach_distance)
