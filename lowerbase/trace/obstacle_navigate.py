"""ObstacleNavigate: goes around what blocks a GTraceList and says where to continue.

On a list (typically TraceNavigate's BLOCKED report) it takes the route from the first segment
with ``finished < 1``, at that fraction, and looks ``lookahead`` metres along it on a global
costmap (lowerbase.navigation: the map's static layer + an obstacle layer marked from every
scan, inflated): the first route pose where the padded footprint meets a LETHAL cell is the
obstacle; the rejoin point is the first pose after it from which ``rejoin_margin`` of route is
clear. The navigation's GlobalPlanner plans to the rejoin point (facing along the route) and the
PathController drives the plan, replanning every ``replan_period`` as the scan shows more of the
obstacle. At the rejoin point it reports FINISHED with ``finished`` updated: the segments before
the rejoin segment 1, the rejoin segment the fraction where it rejoined; so the business node
sends that list back to TraceNavigate, which resumes there. Nothing in the way: FINISHED at
once, ``finished`` unchanged.

Failure is reported as BLOCKED (the seed's only failing status): no clear rejoin point within
``lookahead``, no plan to it, or the detour stopped by an obstacle for ``max_blocked_detour``.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from lowerbase.clock import Clock
from lowerbase.errors import LowerbaseError
from lowerbase.navigation.controller import Status
from lowerbase.navigation.costmap import CostmapParams, LayeredCostmap, global_costmap
from lowerbase.navigation.planner import INSCRIBED, LETHAL, FootprintCells, GlobalPlanner
from lowerbase.trace import messages as m
from lowerbase.trace.base import Navigator, Pose, Publish, PublishSpeed, TraceParams
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import LaserScan

log = logging.getLogger(__name__)
STEP = 0.05  #: [m] route sampling


class ObstacleNavigate(Navigator):
    name = "ObstacleNavigate"

    def __init__(self, clock: Clock, grid: OccupancyGrid, publish: Publish,
                 publish_speed: PublishSpeed, params: TraceParams | None = None,
                 **kwargs: Any) -> None:
        kwargs.setdefault("extent", grid.extent)
        super().__init__(clock, publish, publish_speed, params, **kwargs)
        self.costmap: LayeredCostmap = global_costmap(grid, CostmapParams(obstacles=True))
        self.cells = FootprintCells(self.footprint.points, grid.resolution)
        self.samples = np.empty((0, 5))  #: (segment, fraction, x, y, heading) along the route
        self.rejoin: int | None = None  #: index into samples
        self._next_plan = 0.0
        self._backing = False
        self.reason = ""  #: why the last detour failed

    def mark(self, pose: Pose, scan: LaserScan) -> None:
        self.costmap.update(pose, scan)

    def accept(self, route: m.Route) -> None:
        self.start(route, route.finished)
        first = next((i for i, f in enumerate(route.finished) if f < 1.0), None)
        rows = []
        budget = self.params.lookahead
        for i in range(first if first is not None else len(route.segments), len(route.segments)):
            seg = route.segments[i]
            t0 = route.finished[i]
            n = max(1, int(seg.length * (1.0 - t0) / STEP))
            for t in np.linspace(t0, 1.0, n + 1)[:-1]:
                x, y = seg.point(float(t))
                rows.append((i, float(t), x, y, seg.heading))
            budget -= seg.length * (1.0 - t0)
            if budget <= 0:
                break
        if first is not None and budget > 0:
            last = route.segments[-1]
            rows.append((len(route.segments) - 1, 1.0, last.x1, last.y1, last.heading))
        self.samples = np.asarray(rows, dtype=float).reshape(-1, 5)
        self.rejoin = None
        if self._replan(first_time=True) and self.pose is not None:
            # first back off straight (the final approach drives backwards): TraceNavigate
            # stopped the robot too close to the obstacle to turn in place
            x, y, yaw = self.pose
            d = self.params.backoff
            self._backing = True
            self.ctl.set_plan([(x - d * math.cos(yaw), y - d * math.sin(yaw), yaw)])

    def _find_rejoin(self) -> int | str | None:
        """Index of the rejoin sample; "clear" when nothing blocks the route; None: none."""
        costs = self.costmap.costs
        s = self.samples
        worst = self.cells.max_cost(costs, self.costmap.origin, s[:, 2], s[:, 3], s[:, 4])
        centre = np.array([self.costmap.cost_at(x, y) for x, y in s[:, 2:4]])
        bad = (worst >= LETHAL) | (centre >= INSCRIBED)
        if not bad.any():
            return "clear"
        last_bad = int(np.nonzero(bad)[0][0])
        need = max(1, round(self.params.rejoin_margin / STEP))
        for j in range(last_bad + 1, len(s)):
            if bad[j]:
                last_bad = j
            elif j - last_bad >= need:
                return j  # the end of the clear stretch: room to turn there
        return None

    def _replan(self, first_time: bool = False) -> bool:
        assert self.route is not None
        self._next_plan = self.clock.now() + self.params.replan_period
        if self.pose is None or not len(self.samples):
            return self._fail("no pose yet, or nothing left of the route")
        found = self._find_rejoin()
        if found == "clear" and first_time:
            self.end(m.FINISHED)
            return False
        if found == "clear":
            return True  # keep the current rejoin point
        if found is None:
            return self._fail(f"no clear rejoin point within {self.params.lookahead:g} m")
        assert isinstance(found, int)
        j = max(found, self.rejoin or 0)
        self.rejoin = j
        _, _, x, y, heading = self.samples[j]
        planner = GlobalPlanner.from_costmap(self.costmap, footprint=self.footprint.points)
        try:
            plan = planner.make_plan(self.pose, (x, y, heading))
        except LowerbaseError as exc:
            return self._fail(str(exc))
        if not plan.ok:
            return self._fail(plan.reason)
        self.ctl.set_plan(plan.poses)
        return True

    def _fail(self, reason: str) -> bool:
        self.reason = reason
        log.warning("%s: the detour failed: %s", self.name, reason)
        self.end(m.BLOCKED)
        return False

    def step(self, pose: Pose) -> None:
        if self._backing:
            cmd = self.drive(self.params.avoid_speed, pose)
            if cmd.status is Status.SUCCEEDED or self.blocked_for >= 1.0:
                self._backing = False
                self._replan()
            return
        if self.clock.now() >= self._next_plan and not self._replan():
            return
        cmd = self.drive(self.params.avoid_speed, pose)
        if cmd.status is Status.SUCCEEDED:
            assert self.rejoin is not None
            seg, t = int(self.samples[self.rejoin, 0]), float(self.samples[self.rejoin, 1])
            for i in range(seg):
                self.finished[i] = 1.0
            self.finished[seg] = t
            self.end(m.FINISHED)
        elif self.blocked_for >= self.params.max_blocked_detour:
            self._fail(f"stopped by an obstacle for {self.params.max_blocked_detour:g} s")

