"""The global planner: a grid search on the inflated costmap, as move_base's navfn/global_planner.

ROS-free. It works on a plain ``uint8`` cost array in costmap_2d's conventions (254 LETHAL,
253 INSCRIBED, 255 NO_INFORMATION, inflation decaying from 252, 0 free; row 0 at the lowest y,
cell (row, col) starting at ``origin + (col, row) * resolution``), so any costmap implementation
can feed it (:meth:`GlobalPlanner.from_costmap` takes an object with ``costs``/``data``,
``resolution`` and ``origin``).

The search is scikit-image's :class:`skimage.graph.MCP_Geometric` (Dijkstra in C, 8-connected,
diagonal steps weighted by sqrt 2): lethal and inscribed cells (and unknown ones unless
``allow_unknown``) are impassable, every other cell costs ``1 + cost / cost_scale`` per cell
length, and ``narrow_penalty`` times that from ``narrow_cost`` up (the Navigator passes the
circumscribed cost: where the footprint fits only at some headings, such as a gap beside a
pillar barely wider than the robot, so the search takes such a passage only when the way round
is ``narrow_penalty`` times longer). The cell path is then shortened by line-of-sight
shortcuts that never pass a cell costlier than the worst one of the stretch they replace (so a
shortcut does not hug a wall the search avoided), resampled every ``resolution`` metres, and
given orientations: each pose faces the next one, the last pose takes the goal's yaw.

:meth:`GlobalPlanner.make_plan` has nav_msgs/GetPlan's semantics: a goal that is blocked (or
unreachable) still plans to the reachable free cell nearest to it within ``tolerance`` metres;
with none, the plan is empty and says why. A start in a lethal or inscribed cell, outside the
map or not finite is a :class:`PlanningError`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from skimage import draw
from skimage.graph import MCP_Geometric

from lowerbase.errors import WorldError
from lowerbase.navigation.kernels import footprint_max, footprint_max_at
from lowerbase.text import point

LETHAL = 254
INSCRIBED = 253
NO_INFORMATION = 255
FREE = 0
#: cell indices are clamped to +-this (a point at 1e308 m would overflow math.floor)
_FAR = 1e15
#: a pose faces from this far behind it to this far ahead along the path [m]
HEADING_SPAN = 0.25

Pose = tuple[float, float, float]


class PlanningError(WorldError):
    """A planning request that cannot be answered: a start in an obstacle, a NaN pose."""


@dataclass(frozen=True)
class Plan:
    """A global plan: ``poses`` (x, y, yaw) in the map frame from start to goal (empty when
    there is no path), ``reason`` why not (empty on success), ``goal`` the pose actually planned
    to (the requested goal, or the nearest reachable cell within the tolerance)."""

    poses: list[Pose] = field(default_factory=list)
    reason: str = ""
    goal: Pose | None = None

    @property
    def ok(self) -> bool:
        return bool(self.poses)

    @property
    def length(self) -> float:
        """Path length [m]."""
        if len(self.poses) < 2:
            return 0.0
        xy = np.asarray([(p[0], p[1]) for p in self.poses])
        return float(np.hypot(*np.diff(xy, axis=0).T).sum())


def _finite_pose(pose: Sequence[float], what: str) -> Pose:
    try:
        x, y, yaw = (float(v) for v in pose)
    except (TypeError, ValueError):
        raise PlanningError(f"the {what} is (x, y, yaw) numbers, got {pose!r}") from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise PlanningError(f"the {what} must be finite numbers, got ({x}, {y}, {yaw})")
    return x, y, yaw


class FootprintCells:
    """The cells a footprint covers, per heading: ``max_cost(costs, x, y, yaw)`` (vectorised)
    is the highest cost under the footprint placed at each pose, as costmap_2d's
    footprintCost does with the polygon's outline and interior. Headings are binned to
    ``bins`` per turn; the polygon is rasterised (skimage.draw) grown by what these cells cannot
    resolve: half a cell plus the bin's sweep at the outermost vertex
    polygon (the pose's place inside its cell and the heading's bin) and its outline's cells
    count, so a corner never slips past a wall."""

    def __init__(self, points: Sequence[tuple[float, float]], resolution: float,
                 bins: int = 144) -> None:
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.isfinite(pts).all():
            raise PlanningError(f"a footprint is at least 3 finite [x, y] points, got {points!r}")
        self.points = pts
        self.resolution = float(resolution)
        self.bins = bins
        grow = 0.5 * self.resolution + np.hypot(pts[:, 0], pts[:, 1]).max() * math.pi / bins
        norm = np.hypot(pts[:, 0], pts[:, 1])[:, None]
        grown = pts + pts / np.maximum(norm, 1e-9) * grow
        self.offsets: list[tuple[np.ndarray, np.ndarray]] = []
        for k in range(bins):
            yaw = 2.0 * math.pi * k / bins
            c, s = math.cos(yaw), math.sin(yaw)
            xs = (c * grown[:, 0] - s * grown[:, 1]) / self.resolution
            ys = (s * grown[:, 0] + c * grown[:, 1]) / self.resolution
            n = math.ceil(float(np.abs(np.concatenate((xs, ys))).max())) + 1
            rr, cc = draw.polygon(ys + n, xs + n, shape=(2 * n + 1, 2 * n + 1))
            pr, pc = draw.polygon_perimeter(np.round(ys + n), np.round(xs + n),
                                            shape=(2 * n + 1, 2 * n + 1))
            cells = np.unique(np.concatenate((np.column_stack((rr, cc)),
                                              np.column_stack((pr, pc)))), axis=0) - n
            self.offsets.append((cells[:, 0], cells[:, 1]))
        # every bin's cells in one (bins, L) array each (row and column offsets), short bins
        # padded with their first cell (a repeated cell changes neither the max nor "any cell
        # off the map"): what the compiled footprint checks take
        size = max(dr.size for dr, _ in self.offsets)
        self.dr_table = np.stack([np.pad(dr, (0, size - dr.size), mode="edge")
                             for dr, _ in self.offsets])
        self.dc_table = np.stack([np.pad(dc, (0, size - dc.size), mode="edge")
                             for _, dc in self.offsets])

    def max_cost(self, costs: np.ndarray, origin: Sequence[float], x: np.ndarray | float,
                 y: np.ndarray | float, yaw: np.ndarray | float) -> np.ndarray:
        """Highest cost under the footprint at each pose; LETHAL where it leaves the map."""
        if costs.dtype == np.uint8 and isinstance(x, np.ndarray) and isinstance(y, np.ndarray) \
                and isinstance(yaw, np.ndarray) and x.ndim == 1 and x.shape == y.shape \
                == yaw.shape and x.dtype == y.dtype == yaw.dtype == np.float64:
            # 1D float poses (the controller's arc, the path ahead): one compiled call
            out = np.empty(x.size, dtype=np.int64)
            footprint_max_at(costs, float(origin[0]), float(origin[1]), self.resolution, x, y,
                             yaw, self.bins, self.dr_table, self.dc_table, LETHAL,
                             NO_INFORMATION, out)
            return out
        x, y, yaw = np.broadcast_arrays(np.atleast_1d(np.asarray(x, dtype=np.float64)),
                                        np.atleast_1d(np.asarray(y, dtype=np.float64)),
                                        np.atleast_1d(np.asarray(yaw, dtype=np.float64)))
        rows = np.floor((y - origin[1]) / self.resolution).astype(np.int64)
        cols = np.floor((x - origin[0]) / self.resolution).astype(np.int64)
        k = np.round(np.mod(yaw, 2.0 * math.pi) / (2.0 * math.pi) * self.bins).astype(
            np.int64) % self.bins
        h, w = costs.shape
        if costs.dtype == np.uint8:  # all poses at once, compiled (kernels.py)
            best = np.empty(k.size, dtype=np.int64)
            footprint_max(costs, rows.ravel(), cols.ravel(), k.ravel(), self.dr_table,
                          self.dc_table, LETHAL, NO_INFORMATION, best)
            return best.reshape(x.shape)
        out = np.empty(x.shape, dtype=np.int64)
        for b in np.unique(k):
            sel = k == b
            dr, dc = self.offsets[b]
            r = rows[sel][:, None] + dr[None, :]
            c = cols[sel][:, None] + dc[None, :]
            off = (r < 0) | (c < 0) | (r >= h) | (c >= w)
            vals = costs[np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)].astype(np.int64)
            vals[off] = LETHAL
            vals[vals == NO_INFORMATION] = 0
            out[sel] = vals.max(axis=1)
        return out


#: up to this many goal cells are searched as ends; more: the whole map once (faster)
FEW_ENDS = 256


class GlobalPlanner:
    """Plans on one cost array (see the module docstring). ``cost_scale``: a cell of cost c is
    ``1 + c / cost_scale`` times as long to cross as a free one."""

    def __init__(self, costs: np.ndarray, resolution: float,
                 origin: Sequence[float] = (0.0, 0.0), *, cost_scale: float = 50.0,
                 allow_unknown: bool = False,
                 footprint: Sequence[tuple[float, float]] | None = None,
                 narrow_cost: int | None = None, narrow_penalty: float = 1.0) -> None:
        costs = np.asarray(costs)
        if costs.ndim != 2 or costs.size == 0 or costs.dtype != np.uint8:
            raise PlanningError(f"the costmap must be a non-empty 2D uint8 array, got "
                                f"{costs.dtype} {costs.shape}")
        if not (math.isfinite(resolution) and resolution > 0):
            raise PlanningError(f"the costmap resolution must be > 0 m, got {resolution}")
        if not (math.isfinite(cost_scale) and cost_scale > 0):
            raise PlanningError(f"cost_scale must be > 0, got {cost_scale}")
        if not (math.isfinite(narrow_penalty) and narrow_penalty >= 1.0):
            raise PlanningError(f"narrow_penalty must be >= 1, got {narrow_penalty}")
        self.costs = costs
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))
        self.cost_scale = float(cost_scale)
        self.allow_unknown = allow_unknown
        self.narrow_cost, self.narrow_penalty = narrow_cost, float(narrow_penalty)
        self.footprint = FootprintCells(footprint, self.resolution) \
            if footprint is not None else None
        blocked = costs >= INSCRIBED
        if allow_unknown:
            blocked &= costs != NO_INFORMATION
        self.blocked = blocked
        weights = 1.0 + np.where(costs == NO_INFORMATION, 0, costs).astype(np.float64) \
            / self.cost_scale
        if narrow_cost is not None and narrow_penalty != 1.0:
            weights[(costs >= narrow_cost) & (costs != NO_INFORMATION)] *= narrow_penalty
        weights[blocked] = np.inf
        self.weights = weights

    @classmethod
    def from_costmap(cls, costmap: Any, **kwargs: Any) -> GlobalPlanner:
        """From any costmap object with a uint8 ``costs`` (or ``data``) array, ``resolution``
        and ``origin``."""
        costs = getattr(costmap, "costs", None)
        if costs is None:
            costs = costmap.data
        return cls(np.asarray(costs), costmap.resolution, tuple(costmap.origin)[:2], **kwargs)

    # -- cells and metres -----------------------------------------------------------------------
    def cell(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of a finite map point (may lie outside the grid; a point so far out that
        its index would overflow is clamped, still outside)."""
        r = (y - self.origin[1]) / self.resolution
        c = (x - self.origin[0]) / self.resolution
        return (math.floor(min(max(r, -_FAR), _FAR)), math.floor(min(max(c, -_FAR), _FAR)))

    def outside_by(self, x: float, y: float) -> float:
        """How far [m] the point lies outside the costmap's area (0 on it)."""
        h, w = self.costs.shape
        x0, y0 = self.origin[0], self.origin[1]
        dx = max(x0 - x, 0.0, x - (x0 + w * self.resolution))
        dy = max(y0 - y, 0.0, y - (y0 + h * self.resolution))
        return math.hypot(dx, dy)

    def centre(self, row: int, col: int) -> tuple[float, float]:
        return (self.origin[0] + (col + 0.5) * self.resolution,
                self.origin[1] + (row + 0.5) * self.resolution)

    def inside(self, row: int, col: int) -> bool:
        h, w = self.costs.shape
        return 0 <= row < h and 0 <= col < w

    def cost_at(self, x: float, y: float) -> int:
        """The cost under a map point; LETHAL outside the map."""
        r, c = self.cell(x, y)
        return int(self.costs[r, c]) if self.inside(r, c) else LETHAL

    # -- planning -------------------------------------------------------------------------------
    def make_plan(self, start: Sequence[float], goal: Sequence[float],
                  tolerance: float = 0.0) -> Plan:
        """nav_msgs/GetPlan: a path from ``start`` to ``goal`` (x, y, yaw), or to the reachable
        cell nearest the goal within ``tolerance`` [m]; an empty :class:`Plan` with a reason
        when there is none."""
        sx, sy, _ = _finite_pose(start, "start")
        gx, gy, gyaw = _finite_pose(goal, "goal")
        if not (math.isfinite(tolerance) and tolerance >= 0):
            raise PlanningError(f"the goal tolerance must be >= 0 m, got {tolerance}")
        s_cell = self.cell(sx, sy)
        if not self.inside(*s_cell):
            raise PlanningError(f"the start {point(sx, sy)} is outside the costmap")
        if self.blocked[s_cell]:
            raise PlanningError(
                f"the start {point(sx, sy)} is in an obstacle (cost "
                f"{int(self.costs[s_cell])}): move the robot clear or clear the costmap")
        if self.outside_by(gx, gy) > tolerance:
            return Plan(reason=f"the goal {point(gx, gy)} is outside the costmap by more than "
                               f"the tolerance {tolerance:g} m")
        rows, cols = self._goal_cells(gx, gy, tolerance)
        if rows.size == 0:
            return Plan(reason=f"the goal {point(gx, gy)} is blocked and no free cell "
                               f"lies within the tolerance {tolerance:g} m")
        mcp = MCP_Geometric(self.weights, fully_connected=True)
        if rows.size <= FEW_ENDS:
            ends = list(zip(rows.tolist(), cols.tolist(), strict=True))
            cumulative, _ = mcp.find_costs([s_cell], ends, find_all_ends=True)
        else:  # the whole map once: skimage takes ~30 us per end (a 1e6 m tolerance: 4.6 s)
            cumulative, _ = mcp.find_costs([s_cell])
        reached = np.isfinite(cumulative[rows, cols])
        if not reached.any():
            return Plan(reason=f"no path from {point(sx, sy)} to the goal {point(gx, gy)} "
                               f"within the tolerance {tolerance:g} m")
        i = int(np.argmax(reached))  # candidates are sorted by distance to the goal
        end = (int(rows[i]), int(cols[i]))
        cells = np.asarray(mcp.traceback(end))
        target = (gx, gy) if end == self.cell(gx, gy) else self.centre(*end)
        points = self._smooth(cells, (sx, sy), target)
        poses = _orient(_resample(points, self.resolution), gyaw,
                        max(1, round(HEADING_SPAN / self.resolution)))
        return Plan(poses=poses, goal=(target[0], target[1], gyaw))

    def _goal_cells(self, gx: float, gy: float, tolerance: float
                    ) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the passable cells within ``tolerance`` of the goal, nearest first
        (the goal's own cell first when it is passable)."""
        g_cell = self.cell(gx, gy)
        own = self.inside(*g_cell) and not self.blocked[g_cell]
        first = (np.array([g_cell[0]] if own else [], dtype=np.intp),
                 np.array([g_cell[1]] if own else [], dtype=np.intp))
        h, w = self.costs.shape
        n = min(math.ceil(tolerance / self.resolution) + 1, h + w)  # a huge one: the map
        r0, r1 = max(g_cell[0] - n, 0), min(g_cell[0] + n, h - 1)
        c0, c1 = max(g_cell[1] - n, 0), min(g_cell[1] + n, w - 1)
        if tolerance <= 0 or r1 < r0 or c1 < c0:
            return first
        rows, cols = np.mgrid[r0:r1 + 1, c0:c1 + 1]
        cx = self.origin[0] + (cols + 0.5) * self.resolution
        cy = self.origin[1] + (rows + 0.5) * self.resolution
        dist = np.hypot(cx - gx, cy - gy)
        ok = (dist <= tolerance) & ~self.blocked[r0:r1 + 1, c0:c1 + 1]
        if own:
            ok &= (rows != g_cell[0]) | (cols != g_cell[1])
        order = np.argsort(dist[ok], kind="stable")
        return (np.concatenate([first[0], rows[ok][order]]),
                np.concatenate([first[1], cols[ok][order]]))

    # -- smoothing ------------------------------------------------------------------------------
    def segment_max_cost(self, a: Sequence[float], b: Sequence[float]) -> int:
        """The highest cost the straight segment a -> b passes over (LETHAL off the map);
        impassable cells count as LETHAL."""
        length = math.hypot(b[0] - a[0], b[1] - a[1])
        n = max(2, math.ceil(length / (0.25 * self.resolution)) + 1)
        t = np.linspace(0.0, 1.0, n)
        xs = a[0] + t * (b[0] - a[0])
        ys = a[1] + t * (b[1] - a[1])
        rows = np.floor((ys - self.origin[1]) / self.resolution).astype(np.int64)
        cols = np.floor((xs - self.origin[0]) / self.resolution).astype(np.int64)
        h, w = self.costs.shape
        if rows.min() < 0 or cols.min() < 0 or rows.max() >= h or cols.max() >= w:
            return LETHAL
        if self.blocked[rows, cols].any():
            return LETHAL
        return int(self.costs[rows, cols].max())

    def segment_clear(self, a: Sequence[float], b: Sequence[float], max_cost: int) -> bool:
        """Whether the straight segment a -> b crosses no cell costlier than ``max_cost`` and,
        with a footprint, the footprint facing along it stays off lethal cells."""
        if self.segment_max_cost(a, b) > max_cost:
            return False
        if self.footprint is None:
            return True
        length = math.hypot(b[0] - a[0], b[1] - a[1])
        if length == 0.0:
            return True
        t = np.linspace(0.0, 1.0, max(2, math.ceil(length / self.resolution) + 1))
        yaw = math.atan2(b[1] - a[1], b[0] - a[0])
        cost = self.footprint.max_cost(self.costs, self.origin, a[0] + t * (b[0] - a[0]),
                                       a[1] + t * (b[1] - a[1]), yaw)
        return bool((cost < LETHAL).all())

    def _smooth(self, cells: np.ndarray, start: tuple[float, float],
                goal: tuple[float, float]) -> list[tuple[float, float]]:
        """Line-of-sight shortcuts over the cell path, from the exact start to the exact goal:
        from each kept point the farthest later point reachable in a straight line (found by
        doubling then bisection) whose segment crosses no cell costlier than the worst cell of
        the stretch it replaces (and keeps the footprint off lethal cells)."""
        xs = self.origin[0] + (cells[:, 1] + 0.5) * self.resolution
        ys = self.origin[1] + (cells[:, 0] + 0.5) * self.resolution
        pts = [start, *list(zip(xs.tolist(), ys.tolist(), strict=True))[1:-1], goal]
        cell_cost = np.concatenate(([self.cost_at(*start)],
                                    self.costs[cells[1:-1, 0], cells[1:-1, 1]].astype(int),
                                    [self.cost_at(*goal)])) if len(cells) > 1 else \
            np.asarray([self.cost_at(*start), self.cost_at(*goal)])
        out = [pts[0]]
        i, last = 0, len(pts) - 1
        while i < last:
            worst = np.maximum.accumulate(cell_cost[i:])

            def ok(j: int, i: int = i, worst: np.ndarray = worst) -> bool:
                return self.segment_clear(pts[i], pts[j], int(worst[j - i]))

            good, step = i + 1, 1
            bad = None
            while True:  # doubling
                j = min(i + step, last)
                if j > good and not ok(j):
                    bad = j
                    break
                good = j
                if j == last:
                    break
                step *= 2
            if bad is not None:
                while bad - good > 1:  # bisection between a clear and a blocked one
                    mid = (good + bad) // 2
                    if ok(mid):
                        good = mid
                    else:
                        bad = mid
            out.append(pts[good])
            i = good
        return out


def _resample(points: list[tuple[float, float]], step: float) -> list[tuple[float, float]]:
    """Points every ``step`` metres (at most) along the polyline, its vertices kept."""
    out = [points[0]]
    for (ax, ay), (bx, by) in itertools.pairwise(points):
        n = max(1, math.ceil(math.hypot(bx - ax, by - ay) / step - 1e-9))
        for k in range(1, n + 1):
            out.append((ax + (bx - ax) * k / n, ay + (by - ay) * k / n))
    return out


def _orient(points: list[tuple[float, float]], goal_yaw: float, span: int) -> list[Pose]:
    """Each pose faces along the path: the direction from ``span`` points behind to ``span``
    points ahead (a heading that does not follow the cell path's zigzag); the last pose takes
    ``goal_yaw`` (a one-point path: it too)."""
    if len(points) == 1:
        return [(points[0][0], points[0][1], goal_yaw)]
    xy = np.asarray(points)
    n = len(xy)
    idx = np.arange(n - 1)
    ahead = xy[np.minimum(idx + span, n - 1)]
    behind = xy[np.maximum(idx - span, 0)]
    d = ahead - behind
    yaw = np.arctan2(d[:, 1], d[:, 0])
    poses = [(float(x), float(y), float(a)) for (x, y), a in zip(xy[:-1], yaw, strict=True)]
    poses.append((float(xy[-1, 0]), float(xy[-1, 1]), goal_yaw))
    return poses
