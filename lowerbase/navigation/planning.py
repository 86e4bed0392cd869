"""The Navigator's planning: the planner it builds for the navigation mode, /make_plan, and
a plan through a goal's waypoints: :class:`GoalPlanner`.

The planner runs on the combined costs (the global costmap with the local marks pasted in,
``combined``) with the mode's keep-out around new obstacles (the inscribed radius in a fuzzy
mode, else the circumscribed one, plus ``clearance_margin``) and its cost scale. A start inside
an obstacle's inflation (after a localization error) is planned out of first
(:func:`~lowerbase.navigation.goals.unblocked_start`). :func:`drive_reversed` decides whether
a plan is driven backwards (the mode's ``nav_dir``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from lowerbase.navigation.combined import CombinedCosts
from lowerbase.navigation.controller import wrap
from lowerbase.navigation.costmap import LayeredCostmap
from lowerbase.navigation.goals import NavigatorConfig, Pose, _pose, unblocked_start
from lowerbase.navigation.modes import NavDir, NavigationModeGoal
from lowerbase.navigation.planner import FootprintCells, GlobalPlanner, Plan, PlanningError


class GoalPlanner:
    """Plans on ``combined`` for the Navigator (see the module docstring); ``footprint`` is
    the forward footprint's cells the planner checks."""

    def __init__(self, config: NavigatorConfig, global_cm: LayeredCostmap,
                 combined: CombinedCosts, resolution: float) -> None:
        self.config = config
        self.global_costmap = global_cm
        self.combined = combined
        self.resolution = resolution
        self.plans = 0  #: plans made for goals (not /make_plan requests)

    def clearance(self, mode: NavigationModeGoal) -> float:
        """[m] kept from new obstacles in ``mode``."""
        cm = self.global_costmap
        r = cm.inscribed_radius if mode.fuzzy else cm.circumscribed_radius
        return r + self.config.clearance_margin

    def planner(self, mode: NavigationModeGoal, footprint: FootprintCells, *,
                snapshot: bool = False) -> GlobalPlanner:
        """A planner on the combined costs (``snapshot``: on a copy of them)."""
        fuzzy = mode.fuzzy
        cfg = self.config
        costs = self.combined.planning_costs(self.clearance(mode))
        planner = GlobalPlanner(np.array(costs) if snapshot else costs,
                                self.resolution, self.combined.origin,
                                cost_scale=cfg.fuzzy_cost_scale if fuzzy else cfg.cost_scale,
                                narrow_cost=self.global_costmap.circumscribed_cost,
                                narrow_penalty=1.0 if fuzzy else cfg.narrow_penalty)
        planner.footprint = footprint
        return planner

    def make_plan(self, start: Sequence[float], goal: Sequence[float], tolerance: float,
                  mode: NavigationModeGoal, footprint: FootprintCells) -> Plan:
        """/move_base/make_plan (see :meth:`Navigator.make_plan`)."""
        return self.plan_job(start, goal, tolerance, mode, footprint)()

    def plan_job(self, start: Sequence[float], goal: Sequence[float], tolerance: float,
                 mode: NavigationModeGoal, footprint: FootprintCells) -> Callable[[], Plan]:
        """:meth:`make_plan` in two halves: this one takes a copy of the costs (under the
        caller's lock), the returned call plans on the copy (outside it: the controller goes
        on meanwhile)."""
        planner = self.planner(mode, footprint, snapshot=True)
        s = _pose(start, "start")
        inscribed = self.global_costmap.inscribed_radius

        def plan() -> Plan:
            chosen = planner
            r, c = chosen.cell(s[0], s[1])
            if chosen.inside(r, c) and chosen.blocked[r, c]:
                chosen = unblocked_start(chosen, s, inscribed)
            return chosen.make_plan(s, goal, tolerance)

        return plan

    def through(self, pose: Pose, goals: Sequence[Pose], mode: NavigationModeGoal,
                footprint: FootprintCells) -> tuple[list[Pose], list[int]] | str:
        """One path from ``pose`` through ``goals`` (a plan per leg, joined) and the path index
        where each goal is; or why there is none."""
        poses: list[Pose] = []
        ends: list[int] = []
        start = pose
        try:
            for goal in goals:
                plan = self.make_plan(start, goal, self.config.goal_tolerance, mode, footprint)
                if not plan.ok:
                    return plan.reason
                poses.extend(plan.poses if not poses else plan.poses[1:])
                ends.append(len(poses) - 1)
                start = poses[-1]
        except PlanningError as exc:
            return str(exc)
        self.plans += 1
        return poses, ends


def drive_reversed(nav_dir: int, pose: Pose, poses: Sequence[Pose]) -> bool:
    """Whether the plan ``poses`` from ``pose`` is driven backwards: always (BACKWARD), never,
    or (FOLLOW_PATH) when the path point 1 m ahead lies behind the robot."""
    d = NavDir(nav_dir)
    if d is NavDir.BACKWARD:
        return True
    if d is not NavDir.FOLLOW_PATH:
        return False
    x, y, yaw = pose
    ahead = [p for p in poses if math.hypot(p[0] - x, p[1] - y) >= 1.0]
    px, py = (ahead[0][0], ahead[0][1]) if ahead else (poses[-1][0], poses[-1][1])
    if math.hypot(px - x, py - y) < 1e-6:
        return False
    return abs(wrap(math.atan2(py - y, px - x) - yaw)) > math.pi / 2
