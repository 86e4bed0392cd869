"""TraceNavigate: follows a GTraceList's directed segments in order (shared/seeds/001).

- **Start**: a list whose segments all have ``finished == 0`` starts at the nearest allowed
  start: the first points marked ``starter`` (none marked: the first segment). A list with some
  ``finished > 0`` (a remainder, e.g. from ObstacleNavigate) resumes at the first segment with
  ``finished < 1``, from that fraction on. Segments before the start keep their ``finished``.
  A robot farther than ``APPROACH`` from that start point first drives straight to it and
  turns along the segment (the approach counts as no segment's progress), so the route is
  driven from its start, never cut into at the nearest point.
- **Driving**: consecutive segments that join (within 5 cm) and turn by at most
  ``JOIN_TURN`` are one plan for the navigation's PathController (no stop between them); at a
  sharper joint the robot stops and turns in place. A segment is driven at its first point's
  ``speed`` (mm/s; absent or <= 0: ``default_speed``), within the chassis' maxLinear. At the
  route's end the robot turns to the last point's ``angle``.
- **Reports**: RUNNING on acceptance and every ``status_period`` (5 s) with each segment's
  ``finished`` (its along-track fraction, 0..1, never decreasing); FINISHED once at the end
  (momentary: the module is IDLE after, and silent on speed).
- **Obstacles**: the controller's collision check on the local costmap stops the robot; it
  waits (RUNNING) and goes on when the way clears; stopped ``blocked_timeout`` (60 s) on end it
  reports BLOCKED (persists) and stops sending speed, so that ObstacleNavigate may drive. A new
  list is then accepted (it replaces the blocked task).
"""

from __future__ import annotations

import math

import numpy as np

from lowerbase.navigation.controller import Status, wrap
from lowerbase.trace import messages as m
from lowerbase.trace.base import Navigator, Pose, sample_segment

JOIN_TURN = math.radians(15.0)  #: joints turning more than this stop and rotate in place
JOIN_GAP = 0.05  #: [m] a segment joins the previous one if it starts this close to its end
STEP = 0.05  #: [m] plan resolution
APPROACH = 0.10  #: [m] farther than this from the route's start: drive to it first


class TraceNavigate(Navigator):
    name = "TraceNavigate"

    def accept(self, route: m.Route) -> None:
        done = list(route.finished)
        if any(f > 0 for f in done):
            first = next((i for i, f in enumerate(done) if f < 1.0), None)
        else:
            first = self._nearest_starter(route)
        self.start(route, done)
        self.runs = self._runs(route, first if first is not None else len(done))
        if not self.runs:
            self.end(m.FINISHED)  # nothing left to drive
            return
        self._approach: bool | None = None  # decided at the first step, from the pose
        self._plan_run()

    def _start_pose(self) -> tuple[float, float, float]:
        assert self.route is not None
        i = self.runs[0][0]
        x, y, yaw = sample_segment(self.route.segments[i], self.finished[i], STEP)[0]
        return float(x), float(y), float(yaw)

    def _plan_approach(self, pose: Pose) -> bool:
        """A straight plan from ``pose`` to the route's start, when it is farther than
        APPROACH; whether one was set."""
        sx, sy, syaw = self._start_pose()
        d = math.hypot(sx - pose[0], sy - pose[1])
        if d <= APPROACH:
            return False
        n = max(1, math.ceil(d / STEP))
        toward = math.atan2(sy - pose[1], sx - pose[0])
        plan = [(pose[0] + (sx - pose[0]) * k / n, pose[1] + (sy - pose[1]) * k / n, toward)
                for k in range(n + 1)]
        plan[-1] = (sx, sy, syaw)
        self.ctl.set_plan(plan)
        return True

    def _nearest_starter(self, route: m.Route) -> int:
        starters = [i for i, s in enumerate(route.segments) if s.starter] or [0]
        if self.pose is None:
            return starters[0]
        x, y, _ = self.pose
        return min(starters, key=lambda i: math.hypot(route.segments[i].x0 - x,
                                                      route.segments[i].y0 - y))

    @staticmethod
    def _runs(route: m.Route, first: int) -> list[list[int]]:
        runs: list[list[int]] = []
        segs = route.segments
        for i in range(first, len(segs)):
            prev = segs[i - 1] if runs else None
            joins = prev is not None and math.hypot(segs[i].x0 - prev.x1,
                                                    segs[i].y0 - prev.y1) <= JOIN_GAP \
                and abs(wrap(segs[i].heading - prev.heading)) <= JOIN_TURN
            if joins:
                runs[-1].append(i)
            else:
                runs.append([i])
        return runs

    def _plan_run(self) -> None:
        assert self.route is not None
        run = self.runs[0]
        parts = [sample_segment(self.route.segments[i], self.finished[i] if k == 0 else 0.0,
                                STEP) for k, i in enumerate(run)]
        poses = np.concatenate([p if k == 0 else p[1:] for k, p in enumerate(parts)])
        if len(self.runs) == 1:
            poses[-1, 2] = self.route.final_angle
        self.ctl.set_plan([(float(a), float(b), float(c)) for a, b, c in poses])

    def step(self, pose: Pose) -> None:
        assert self.route is not None
        if self._approach is None:
            self._approach = self._plan_approach(pose)
        if self._approach:
            cmd = self.drive(self.params.default_speed, pose)
            if cmd.status is Status.SUCCEEDED:
                self._approach = False
                self._plan_run()
            elif self.blocked_for >= self.params.blocked_timeout:
                self.end(m.BLOCKED)
            return
        run = self.runs[0]
        current = next((i for i in run if self.finished[i] < 1.0), run[-1])
        speed = self.route.segments[current].speed or self.params.default_speed
        cmd = self.drive(speed, pose)
        self._progress(run, pose)
        if cmd.status is Status.SUCCEEDED:
            for i in run:
                self.finished[i] = 1.0
            self.runs.pop(0)
            if not self.runs:
                self.end(m.FINISHED)
                return
            self._plan_run()
        elif self.blocked_for >= self.params.blocked_timeout:
            self.end(m.BLOCKED)

    def _progress(self, run: list[int], pose: Pose) -> None:
        assert self.route is not None
        for i in run:
            if self.finished[i] >= 1.0:
                continue
            t, _ = self.route.segments[i].project(pose[0], pose[1])
            if t >= 1.0 and i != run[-1]:
                self.finished[i] = 1.0
                continue
            self.finished[i] = max(self.finished[i], min(max(t, 0.0), 1.0 if i != run[-1]
                                                         else 0.999))
            break
