"""The controller's compiled arc check (navigation.pursuit_kernels) against the numpy code it
replaced: the arc's poses bit for bit (forward, backward, straight, in place, tiny and huge
speeds) and the verdict equal to ``(FootprintCells.max_cost >= LETHAL).any()`` on random
costmaps with every cost class, on, near and off the map; the path bookkeeping equal to numpy's
argmin and first match; and the controller's commands over whole drives (a unicycle on the
commands, past an obstacle) equal to those of the controller with its numpy methods."""

from __future__ import annotations

import math

import numpy as np

from lowerbase.navigation.controller import Command, PathController, Status
from lowerbase.navigation.planner import LETHAL, NO_INFORMATION, FootprintCells, GlobalPlanner
from lowerbase.navigation.pursuit_kernels import (
    arc_hits_lethal,
    arc_poses,
    first_beyond,
    nearest_ahead,
)
from lowerbase.world.footprint import DEFAULT_POINTS
from tests.navigation.footprint_reference import reference_max_cost


def numpy_arc(x: float, y: float, yaw: float, v: float, w: float, reach: float, turn: float,
              n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PathController._checked's arc as it was in numpy (before pursuit_kernels)."""
    s = np.arange(1, n + 1, dtype=np.float64)
    s *= 1.0 / n
    s[-1] = 1.0
    direction = 1.0 if v >= 0 else -1.0
    if abs(v) > 1e-6:
        t = s * (reach / abs(v))
    else:
        t = s * (turn / max(abs(w), 1e-6))
        direction = 0.0
    th = yaw + w * t
    vv = direction * abs(v) if direction else 0.0
    if abs(w) > 1e-6 and direction:
        r = vv / w
        px = x + r * (np.sin(th) - math.sin(yaw))
        py = y - r * (np.cos(th) - math.cos(yaw))
    else:
        px = x + vv * t * math.cos(yaw)
        py = y + vv * t * math.sin(yaw)
    return px, py, th


def _cases(rng: np.random.Generator, count: int) -> list[tuple[float, ...]]:
    cases = []
    for i in range(count):
        v = float(rng.choice([0.0, 1e-7, -1e-7, 1e-3]) if i % 5 == 0
                  else rng.uniform(-1.2, 1.2))
        w = float(rng.choice([0.0, 1e-7, -2e-6]) if i % 7 == 0 else rng.uniform(-1.0, 1.0))
        reach = float(rng.uniform(0.01, 1.0))
        turn = float(rng.uniform(0.05, 0.8))
        cases.append((float(rng.uniform(-1, 6)), float(rng.uniform(-1, 4)),
                      float(rng.uniform(-8, 8)), v, w, reach, turn))
    return cases


def test_arc_poses_are_the_numpy_arc_bit_for_bit() -> None:
    rng = np.random.default_rng(21)
    for x, y, yaw, v, w, reach, turn in _cases(rng, 3000):
        n = int(rng.integers(1, 60))
        out = np.empty((n, 3))
        arc_poses(x, y, yaw, v, w, reach, turn, n, out)
        px, py, th = numpy_arc(x, y, yaw, v, w, reach, turn, n)
        assert out[:, 0].tobytes() == px.tobytes()
        assert out[:, 1].tobytes() == py.tobytes()
        assert out[:, 2].tobytes() == th.tobytes()


def test_the_verdict_is_the_footprint_gathers() -> None:
    rng = np.random.default_rng(5)
    fc = FootprintCells([(float(px), float(py)) for px, py in DEFAULT_POINTS], 0.05)
    costs = rng.choice(np.array([0, 0, 0, 0, 5, 128, 252, 253, NO_INFORMATION], np.uint8),
                       size=(90, 120))
    lethal = rng.integers(0, costs.size, 40)
    costs.flat[lethal] = LETHAL  # sparse: arcs both clear and blocked
    origin = (-0.5, -1.0)
    seen = set()
    for x, y, yaw, v, w, reach, turn in _cases(rng, 1500):
        n = int(rng.integers(3, 40))
        px, py, th = numpy_arc(x, y, yaw, v, w, reach, turn, n)
        want = bool((reference_max_cost(fc, costs, origin, px, py, th) >= LETHAL).any())
        got = arc_hits_lethal(costs, origin[0], origin[1], fc.resolution, x, y, yaw, v, w,
                              reach, turn, n, fc.bins, fc.dr_table, fc.dc_table, LETHAL,
                              NO_INFORMATION)
        assert got == want, (x, y, yaw, v, w, reach, turn, n)
        seen.add(want)
    assert seen == {True, False}


def test_path_bookkeeping_is_numpys() -> None:
    rng = np.random.default_rng(9)
    for _ in range(2000):
        n = int(rng.integers(1, 80))
        path = np.round(rng.uniform(0, 4, (n, 3)), int(rng.integers(1, 4)))  # ties too
        x, y = (float(v) for v in np.round(rng.uniform(0, 4, 2), 1))
        start = int(rng.integers(0, n))
        end = min(n, start + int(rng.integers(1, 50)))
        seg = path[start:end, :2]
        want = start + int(np.argmin(np.hypot(seg[:, 0] - x, seg[:, 1] - y)))
        assert nearest_ahead(path, start, end, x, y) == want
        ld = float(rng.uniform(0, 3))
        rest = path[start:, :2]
        beyond = np.flatnonzero(np.hypot(rest[:, 0] - x, rest[:, 1] - y) >= ld)
        want = start + int(beyond[0]) if beyond.size else n - 1
        assert first_beyond(path, start, x, y, ld) == want


class NumpyController(PathController):
    """The controller with its methods as they were in numpy (before pursuit_kernels)."""

    def _advance(self, x: float, y: float) -> None:
        end = min(len(self.path), self._index + max(20, int(2.0 / self.resolution)))
        seg = self.path[self._index:end, :2]
        self._index += int(np.argmin(np.hypot(seg[:, 0] - x, seg[:, 1] - y)))

    def _carrot(self, x: float, y: float, tight: bool = False) -> tuple[float, float]:
        cfg = self.config
        ld = min(max(cfg.lookahead * abs(self.v) / cfg.max_speed, cfg.min_lookahead),
                 cfg.lookahead)
        if tight:
            ld = 0.5 * cfg.min_lookahead
        rest = self.path[self._index:, :2]
        beyond = np.flatnonzero(np.hypot(rest[:, 0] - x, rest[:, 1] - y) >= ld)
        k = int(beyond[0]) if beyond.size else len(rest) - 1
        return float(rest[k, 0]), float(rest[k, 1])

    def _checked(self, x: float, y: float, yaw: float, v: float, w: float,
                 status: Status, up_to: float = math.inf) -> Command:
        v_next, w_next = self._ramp(v, w)
        reach, turn, n = self._arc_extent(v_next, w_next, up_to)
        px, py, th = numpy_arc(x, y, yaw, v_next, w_next, reach, turn, n)
        if (self.footprint.max_cost(self.costs, self.origin, px, py, th) >= LETHAL).any():
            v_stop, w_stop = self._ramp(0.0, 0.0)
            return self._out(v_stop, w_stop, Status.BLOCKED, "an obstacle ahead of the robot")
        if status is not self._phase and self._phase is Status.BLOCKED:
            self._phase = status
        return self._out(v_next, w_next, status)


def test_commands_over_whole_drives_are_the_numpy_controllers() -> None:
    res = 0.05
    costs = np.zeros((120, 200), np.uint8)
    costs[0, :] = costs[-1, :] = costs[:, 0] = costs[:, -1] = LETHAL
    costs[40:80, 90:96] = LETHAL  # a pillar between the starts and the goals
    costs[30:90, 84:102] = np.maximum(costs[30:90, 84:102], 120)
    costs[60:62, 150:152] = LETHAL  # dropped onto the costmap later: a block ahead
    planner = GlobalPlanner(costs, res, footprint=DEFAULT_POINTS)
    statuses = set()
    for start, goal in [((1.0, 1.0, 0.3), (9.0, 5.0, 1.0)), ((9.0, 1.0, 3.0), (1.5, 5.0, -2.0)),
                        ((2.0, 3.0, -2.5), (8.5, 3.0, 0.0))]:
        plan = planner.make_plan(start, goal).poses
        assert plan
        fast = PathController(costs, res, footprint=DEFAULT_POINTS)
        ref = NumpyController(costs, res, footprint=DEFAULT_POINTS)
        pose = start
        for ctl in (fast, ref):
            ctl.set_plan(plan)
        for _ in range(1200):
            a, b = fast.compute(pose), ref.compute(pose)
            assert (a.linear, a.angular, a.status, a.reason) == \
                (b.linear, b.angular, b.status, b.reason)
            assert fast._index == ref._index
            statuses.add(a.status)
            if a.status is Status.SUCCEEDED or (a.status is Status.BLOCKED and a.linear == 0.0
                                                and a.angular == 0.0):
                break
            x, y, yaw = pose
            pose = (x + a.linear * 0.05 * math.cos(yaw), y + a.linear * 0.05 * math.sin(yaw),
                    yaw + a.angular * 0.05)
    assert {Status.ROTATING, Status.FOLLOWING, Status.APPROACHING, Status.SUCCEEDED,
            Status.BLOCKED} <= statuses
