"""costmap_2d's layers without ROS: the grid, static, obstacle and inflation layers.

Costs follow costmap_2d (``cost_values.h``): 0 free, 1..252 inflation decaying with distance,
253 INSCRIBED (the robot's centre there means a collision), 254 LETHAL, 255 NO_INFORMATION.
Every layer works on whole arrays (numpy, scipy, scikit-image); there is no per-cell Python loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from skimage import draw

from lowerbase.errors import ConfigError, WorldError
from lowerbase.navigation.kernels import (
    clear_lines,
    inflate,
    mark_points,
    polygon_cells,
    ray_end_cells,
    squared_distances,
)
from lowerbase.navigation.kernels import combine_max as _combine_max
from lowerbase.world.footprint import Footprint
from lowerbase.world.grid import OccupancyGrid


def _polygon_perimeter(r: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cells of skimage's ``polygon_perimeter(r, c)`` (integer vertices, no shape): its
    Bresenham lines (``draw.line``) along the closed outline, without the version check and the
    matplotlib clip to the polygon's own bounding box it does on every call (about 1 ms, more
    than the drawing). The same cells: tests/navigation/test_layers_perimeter.py."""
    rr, cc = [], []
    n = len(r)
    for i in range(n):
        j = (i + 1) % n
        line_r, line_c = draw.line(int(r[i]), int(c[i]), int(r[j]), int(c[j]))
        rr.append(line_r)
        cc.append(line_c)
    return np.concatenate(rr), np.concatenate(cc)


FREE_SPACE = 0
MAX_NON_OBSTACLE = 252
INSCRIBED_INFLATED_OBSTACLE = 253
LETHAL_OBSTACLE = 254
NO_INFORMATION = 255


class Costmap2D:
    """A uint8 cost grid: ``data[row, col]``, row 0 at the lowest y; cell (row, col) covers the
    square from ``origin + (col, row) * resolution`` (nav_msgs/OccupancyGrid's convention)."""

    def __init__(self, width: int, height: int, resolution: float,
                 origin: tuple[float, float], default: int = FREE_SPACE) -> None:
        if width < 1 or height < 1:
            raise ConfigError(f"a costmap needs at least one cell, got {width} x {height}")
        if not (math.isfinite(resolution) and resolution > 0):
            raise ConfigError(f"costmap resolution must be > 0 m, got {resolution!r}")
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))
        self.default = int(default)
        self.data = np.full((height, width), self.default, np.uint8)

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    def world_to_map(self, x: np.ndarray | float, y: np.ndarray | float
                     ) -> tuple[np.ndarray, np.ndarray]:
        """(col, row) of map-frame points; may lie outside the grid (see :meth:`inside`)."""
        col = np.floor((np.asarray(x, float) - self.origin[0]) / self.resolution)
        row = np.floor((np.asarray(y, float) - self.origin[1]) / self.resolution)
        return col.astype(np.int64), row.astype(np.int64)

    def map_to_world(self, col: np.ndarray | int, row: np.ndarray | int
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Map-frame centres [m] of cells."""
        return (self.origin[0] + (np.asarray(col) + 0.5) * self.resolution,
                self.origin[1] + (np.asarray(row) + 0.5) * self.resolution)

    def inside(self, col: np.ndarray, row: np.ndarray) -> np.ndarray:
        return (col >= 0) & (col < self.width) & (row >= 0) & (row < self.height)

    def reset(self) -> None:
        self.data.fill(self.default)

    def shift_to(self, origin: tuple[float, float]) -> None:
        """costmap_2d's updateOrigin: move the grid by whole cells towards ``origin``, keep what
        overlaps (in world coordinates) and fill the rest with the default value."""
        dc = round((origin[0] - self.origin[0]) / self.resolution)
        dr = round((origin[1] - self.origin[1]) / self.resolution)
        if dc == 0 and dr == 0:
            return
        new = np.full_like(self.data, self.default)
        h, w = self.data.shape
        src_r = slice(max(dr, 0), min(h + dr, h))
        src_c = slice(max(dc, 0), min(w + dc, w))
        dst_r = slice(max(-dr, 0), min(h - dr, h))
        dst_c = slice(max(-dc, 0), min(w - dc, w))
        if src_r.start < src_r.stop and src_c.start < src_c.stop:
            new[dst_r, dst_c] = self.data[src_r, src_c]
        self.data = new
        self.origin = (self.origin[0] + dc * self.resolution,
                       self.origin[1] + dr * self.resolution)

    def polygon_cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """(cols, rows) of the cells a map-frame polygon covers (cells whose centre is inside,
        plus the cells its outline runs through) and whether any part leaves the grid."""
        fc = (xy[:, 0] - self.origin[0]) / self.resolution - 0.5
        fr = (xy[:, 1] - self.origin[1]) / self.resolution - 0.5
        # skimage's draw.polygon and the Bresenham outline of _polygon_perimeter, compiled
        cols, rows, off = polygon_cells(fr, fc, np.round(fr).astype(np.int64),
                                        np.round(fc).astype(np.int64), self.height, self.width)
        return cols, rows, bool(off)


# ---------------------------------------------------------------------------- footprint radii

def footprint_radii(footprint: Footprint) -> tuple[float, float]:
    """costmap_2d's calculateMinAndMaxDistances: (inscribed radius = the distance from the
    origin to the nearest edge, circumscribed radius = the farthest vertex) [m]."""
    pts = np.asarray(footprint.points)
    a, b = pts, np.roll(pts, -1, axis=0)
    ab = b - a
    t = np.clip(-(a * ab).sum(axis=1) / (ab * ab).sum(axis=1), 0.0, 1.0)
    closest = a + t[:, None] * ab
    return float(np.hypot(closest[:, 0], closest[:, 1]).min()), \
        float(np.hypot(pts[:, 0], pts[:, 1]).max())


def footprint_at(footprint: Footprint, pose: tuple[float, float, float]) -> np.ndarray:
    """The footprint's vertices (n, 2) placed at ``pose`` in the map frame."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    p = np.asarray(footprint.points)
    return np.column_stack((x + c * p[:, 0] - s * p[:, 1], y + s * p[:, 0] + c * p[:, 1]))


# ---------------------------------------------------------------------------- static layer

@dataclass(frozen=True)
class StaticParams:
    """costmap_2d's static_layer parameters (names and defaults)."""

    track_unknown_space: bool = True
    lethal_cost_threshold: int = 100
    unknown_cost_value: int = -1
    trinary_costmap: bool = True

    def __post_init__(self) -> None:
        if not 1 <= self.lethal_cost_threshold <= 100:
            raise ConfigError(f"static_layer lethal_cost_threshold = "
                              f"{self.lethal_cost_threshold!r} is invalid; allowed: 1..100")


def interpret(data: np.ndarray, p: StaticParams) -> np.ndarray:
    """StaticLayer::interpretValue on a whole OccupancyGrid array (int8) -> uint8 costs."""
    v = data.astype(np.int16)
    if p.trinary_costmap:
        cost = np.where(v >= p.lethal_cost_threshold, LETHAL_OBSTACLE, FREE_SPACE)
    else:
        scaled = np.floor(np.clip(v, 0, 100) / p.lethal_cost_threshold * LETHAL_OBSTACLE)
        cost = np.where(v >= p.lethal_cost_threshold, LETHAL_OBSTACLE, scaled)
    unknown = NO_INFORMATION if p.track_unknown_space else FREE_SPACE
    return np.where(v == p.unknown_cost_value, unknown, cost).astype(np.uint8)


class StaticLayer:
    """The map's costs, sampled at the cell centres of any (rolling) window; outside the map
    counts as unknown."""

    def __init__(self, grid: OccupancyGrid, params: StaticParams) -> None:
        if grid.origin[2] != 0.0:
            raise WorldError(f"maps with a rotated origin (yaw {grid.origin[2]}) are not "
                             f"supported by the costmaps")
        self.grid = grid
        self.params = params
        self.costs = interpret(grid.data, params)
        self._outside = NO_INFORMATION if params.track_unknown_space else FREE_SPACE
        self._cache: tuple[tuple[float, float, int, int, float], np.ndarray] | None = None

    def window(self, cm: Costmap2D) -> np.ndarray:
        key = (cm.origin[0], cm.origin[1], cm.width, cm.height, cm.resolution)
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        xs, _ = cm.map_to_world(np.arange(cm.width), 0)
        _, ys = cm.map_to_world(0, np.arange(cm.height))
        gc, _ = self.grid.world_to_cell(xs, 0.0)
        _, gr = self.grid.world_to_cell(0.0, ys)
        okc = (gc >= 0) & (gc < self.grid.width)
        okr = (gr >= 0) & (gr < self.grid.height)
        out = np.full((cm.height, cm.width), self._outside, np.uint8)
        out[np.ix_(okr, okc)] = self.costs[np.ix_(gr[okr], gc[okc])]
        self._cache = (key, out)
        return out


# ---------------------------------------------------------------------------- obstacle layer

def line_cells(c0: int, r0: int, c1: np.ndarray, r1: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """All cells of the lines from (c0, r0) to each (c1, r1), end cells included: one cell per
    step along each line's major axis (the cells Bresenham's algorithm visits), batched."""
    dc, dr = c1 - c0, r1 - r0
    n = np.maximum(np.abs(dc), np.abs(dr))
    counts = n + 1
    which = np.repeat(np.arange(n.size), counts)
    step = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    frac = step / np.maximum(n, 1)[which]
    cols = c0 + np.floor(frac * dc[which] + 0.5).astype(np.int64)
    rows = r0 + np.floor(frac * dr[which] + 0.5).astype(np.int64)
    return cols, rows


def clip_rays(ox: float, oy: float, ex: np.ndarray, ey: np.ndarray, max_len: float,
              box: tuple[float, float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """End points of rays from (ox, oy) towards (ex, ey), shortened to ``max_len`` and to the
    box (xmin, ymin, xmax, ymax) that contains the origin (costmap_2d's raycastFreespace)."""
    dx, dy = ex - ox, ey - oy
    length = np.hypot(dx, dy)
    t = np.minimum(1.0, max_len / np.maximum(length, 1e-12))
    xmin, ymin, xmax, ymax = box
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(dx > 0, (xmax - ox) / dx, np.where(dx < 0, (xmin - ox) / dx, np.inf))
        ty = np.where(dy > 0, (ymax - oy) / dy, np.where(dy < 0, (ymin - oy) / dy, np.inf))
    t = np.minimum(t, np.minimum(tx, ty))
    return ox + t * dx, oy + t * dy


@dataclass(frozen=True)
class Observation:
    """One sensor reading in the map frame, as costmap_2d's Observation: the sensor's
    ``origin`` (x, y, z) [m], ``points`` (n, 3) [m] (returns) and the source's limits."""

    origin: tuple[float, float, float]
    points: np.ndarray
    obstacle_range: float = 2.5
    raytrace_range: float = 3.0
    min_obstacle_height: float = 0.0
    max_obstacle_height: float = 2.0
    marking: bool = True
    clearing: bool = True


class ObstacleLayer:
    """costmap_2d's obstacle_layer: its own grid, cleared along each ray from the sensor and
    marked LETHAL at each return within ``obstacle_range`` and the height limits."""

    def __init__(self, like: Costmap2D, track_unknown_space: bool = False,
                 max_obstacle_height: float = 2.0) -> None:
        self.max_obstacle_height = max_obstacle_height
        self.map = Costmap2D(like.width, like.height, like.resolution, like.origin,
                             NO_INFORMATION if track_unknown_space else FREE_SPACE)

    def reset(self) -> None:
        self.map.reset()

    def clear_cells(self, cols: np.ndarray, rows: np.ndarray) -> None:
        self.map.data[rows, cols] = FREE_SPACE

    def update(self, observations: list[Observation]) -> None:
        """All clearing first, then all marking (ObstacleLayer::updateBounds)."""
        cm = self.map
        box = (cm.origin[0], cm.origin[1], cm.origin[0] + cm.width * cm.resolution - 1e-9,
               cm.origin[1] + cm.height * cm.resolution - 1e-9)
        for obs in observations:
            if not obs.clearing or obs.points.size == 0:
                continue
            oc, orow = cm.world_to_map(obs.origin[0], obs.origin[1])
            if not cm.inside(oc, orow):
                continue  # costmap_2d: "sensor origin out of map bounds", no clearing
            # the rays clipped (clip_rays) and their end cells on the grid, then the cells of
            # line_cells to every (distinct) end cell, compiled (kernels.py)
            n = obs.points.shape[0]
            ec, er = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
            ray_end_cells(float(obs.origin[0]), float(obs.origin[1]),
                          np.ascontiguousarray(obs.points[:, 0], dtype=float),
                          np.ascontiguousarray(obs.points[:, 1], dtype=float),
                          float(obs.raytrace_range), *box, float(cm.origin[0]),
                          float(cm.origin[1]), float(cm.resolution), cm.width, cm.height,
                          ec, er)
            clear_lines(cm.data, int(oc), int(orow), ec, er, FREE_SPACE)
        for obs in observations:
            if not obs.marking or obs.points.size == 0:
                continue
            # LETHAL on the cell of every return within the height limits and obstacle_range,
            # compiled (kernels.py; the numpy marking is tests/navigation/test_mark_points.py's)
            p = np.asarray(obs.points, dtype=float)
            top = min(obs.max_obstacle_height, self.max_obstacle_height)
            mark_points(cm.data, p[:, 0], p[:, 1], p[:, 2], float(obs.origin[0]),
                        float(obs.origin[1]), float(obs.origin[2]),
                        float(obs.min_obstacle_height), float(top),
                        float(obs.obstacle_range ** 2), float(cm.origin[0]),
                        float(cm.origin[1]), float(cm.resolution), LETHAL_OBSTACLE)


def combine_max(master: np.ndarray, layer: np.ndarray) -> None:
    """costmap_2d's updateWithMax: the layer's known cells raise the master (in place);
    a master cell without information takes the layer's value."""
    if master.dtype == np.uint8 and layer.dtype == np.uint8 and master.ndim == 2 \
            and master.shape == layer.shape:  # compiled (kernels.py), the same cells
        _combine_max(master, layer, NO_INFORMATION)
        return
    known = layer != NO_INFORMATION
    take = known & ((master == NO_INFORMATION) | (master < layer))
    master[take] = layer[take]


# ---------------------------------------------------------------------------- inflation layer

@dataclass(frozen=True)
class InflationParams:
    """costmap_2d's inflation_layer parameters (names and defaults)."""

    inflation_radius: float = 0.55
    cost_scaling_factor: float = 10.0
    inflate_unknown: bool = False

    def __post_init__(self) -> None:
        for key in ("inflation_radius", "cost_scaling_factor"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= 100):
                raise ConfigError(f"inflation_layer {key} = {v!r} is invalid; allowed: 0..100")


def inflation_cost(distance_m: np.ndarray | float, inscribed_radius: float,
                   cost_scaling_factor: float) -> np.ndarray:
    """InflationLayer::computeCost for distances [m] from a lethal cell (no radius cut-off)."""
    d = np.asarray(distance_m, float)
    decay = np.floor(MAX_NON_OBSTACLE * np.exp(-cost_scaling_factor * (d - inscribed_radius)))
    cost = np.where(d <= inscribed_radius, INSCRIBED_INFLATED_OBSTACLE, decay)
    return np.where(d == 0, LETHAL_OBSTACLE, cost).astype(np.uint8)


class InflationLayer:
    """Costs decaying away from every LETHAL cell of the master grid, out to
    ``inflation_radius``: exact squared cell distances to the nearest LETHAL cell (compiled,
:func:`~lowerbase.navigation.kernels.squared_distances`) and a lookup by them."""

    def __init__(self, params: InflationParams) -> None:
        self.params = params
        self._table = np.zeros(1, np.uint8)
        self._key: tuple[float, float, float] | None = None

    def table(self, resolution: float, inscribed_radius: float) -> np.ndarray:
        """Cost by squared distance in cells, 0 beyond the cell inflation radius."""
        key = (resolution, inscribed_radius, self.params.inflation_radius)
        if key != self._key:
            cells = math.ceil(max(self.params.inflation_radius, 0.0) / resolution)
            d2 = np.arange(cells * cells + 2)
            table = inflation_cost(np.sqrt(d2) * resolution, inscribed_radius,
                                   self.params.cost_scaling_factor)
            table[d2 > cells * cells] = FREE_SPACE
            self._table, self._key = table, key
        return self._table

    def apply(self, master: np.ndarray, resolution: float, inscribed_radius: float) -> None:
        """Inflate ``master`` in place (InflationLayer::updateCosts)."""
        lethal = master == LETHAL_OBSTACLE
        if not lethal.any():
            return
        table = self.table(resolution, inscribed_radius)
        # the squared distance to the nearest LETHAL cell, capped where the table ends: the
        # integers rint(edt^2) gave, compiled (kernels.py)
        d2 = np.empty(master.shape, np.int64)
        squared_distances(lethal, table.size - 1, d2)
        floor = 1 if self.params.inflate_unknown else INSCRIBED_INFLATED_OBSTACLE
        if master.dtype == np.uint8 and master.ndim == 2:  # compiled (kernels.py)
            inflate(master, d2, table, NO_INFORMATION, floor)
            return
        infl = table[d2]
        unknown = master == NO_INFORMATION
        np.maximum(master, infl, out=master, where=~unknown)
        take = unknown & (infl >= floor)
        master[take] = infl[take]
