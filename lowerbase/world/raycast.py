"""Exact 2D ray casting, vectorised over rays: the shared core of the lidar and the depth camera.

Grid: a ray enters a new cell exactly where it crosses a vertical (x = const) or horizontal
(y = const) cell boundary. For every ray the crossings are enumerated in closed form, the cell
entered at each is looked up in the occupancy mask (``np.take``), and the first occupied one gives
the hit: the distance is exact (floating point) to the boundary of the first occupied cell the ray
passes through, corner cuts included. The crossings are processed in growing distance chunks and
rays that have hit (or left the grid) drop out, so the cost follows the distances actually
travelled, not the maximum range.

Solids: obstacles the map does not know, as prisms from the floor to a height: polygons (any
simple polygon, as a closed ring of vertices) and circles (people). Ray/segment and ray/circle
intersections are analytic.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from lowerbase.errors import WorldError
from lowerbase.world.grid import OccupancyGrid

FACE_NONE = 0   # no hit, or the ray starts inside an occupied cell
FACE_X = 1      # hit a cell boundary x = const (the face normal is along x)
FACE_Y = 2      # hit a cell boundary y = const

_CHUNKS_CELLS = (16.0, 64.0, 256.0, 1024.0)  # chunk ends [cells]; the last one grows by x4


@dataclass(frozen=True)
class GridHits:
    """Per-ray result of :func:`cast_grid` (arrays of the rays' shape)."""

    distance: np.ndarray  # [m]; inf = nothing occupied within max_range
    face: np.ndarray      # FACE_* of the boundary hit
    face_coord: np.ndarray  # [m] the boundary's x (FACE_X) or y (FACE_Y) in the map frame


def cast_grid(mask: np.ndarray, grid: OccupancyGrid, x0: np.ndarray | float,
              y0: np.ndarray | float, angles: np.ndarray, max_range: float | np.ndarray
              ) -> GridHits:
    """Cast rays from (x0, y0) [m, map frame] at ``angles`` [rad] against ``mask`` (bool, the
    grid's shape, True = occupied). Cells outside the grid are free."""
    if grid.origin[2] != 0.0:
        raise WorldError("sensors need a map whose origin yaw is 0; rotate the map image instead")
    angles = np.asarray(angles, dtype=float)
    shape = angles.shape
    ang = angles.ravel()
    n = ang.size
    res = grid.resolution
    gx = np.broadcast_to((np.asarray(x0, dtype=float) - grid.origin[0]) / res, shape).ravel()
    gy = np.broadcast_to((np.asarray(y0, dtype=float) - grid.origin[1]) / res, shape).ravel()
    u_max = np.broadcast_to(np.asarray(max_range, dtype=float) / res, shape).ravel().copy()
    c, s = np.cos(ang), np.sin(ang)
    h, w = mask.shape
    flat = np.ascontiguousarray(mask, dtype=bool).ravel()

    dist_u = np.full(n, np.inf)
    face = np.zeros(n, dtype=np.int8)
    coord = np.zeros(n)

    col0, row0 = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
    inside0 = (col0 >= 0) & (col0 < w) & (row0 >= 0) & (row0 < h)
    start_hit = np.zeros(n, dtype=bool)
    start_hit[inside0] = flat[row0[inside0] * w + col0[inside0]]
    dist_u[start_hit] = 0.0
    # Leave the grid's box: nothing can be hit beyond it (slab method on [0, w] x [0, h]).
    u_max = np.minimum(u_max, _exit_distance(gx, gy, c, s, w, h))

    active = np.flatnonzero(~start_hit & (u_max > 0))
    lo = 0.0
    hi_iter = iter(_CHUNKS_CELLS)
    hi = next(hi_iter)
    while active.size:
        ux, Xx = _first_hits(flat, w, h, gx[active], gy[active], c[active], s[active],
                                 lo, np.minimum(hi, u_max[active]))
        uy, Yy = _first_hits(flat, h, w, gy[active], gx[active], s[active], c[active],
                                 lo, np.minimum(hi, u_max[active]), transpose=True)
        hit_x = ux <= uy
        u = np.where(hit_x, ux, uy)
        got = np.isfinite(u)
        idx = active[got]
        dist_u[idx] = u[got]
        face[idx] = np.where(hit_x[got], FACE_X, FACE_Y)
        coord[idx] = np.where(hit_x[got], grid.origin[0] + Xx[got] * res,
                              grid.origin[1] + Yy[got] * res)
        active = active[~got & (u_max[active] > hi)]
        lo = hi
        hi = next(hi_iter, hi * 4.0)
    return GridHits((dist_u * res).reshape(shape), face.reshape(shape), coord.reshape(shape))


def _exit_distance(gx: np.ndarray, gy: np.ndarray, c: np.ndarray, s: np.ndarray, w: int,
                   h: int) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 0, (w - gx) / c, np.where(c < 0, -gx / c, np.inf))
        ty = np.where(s > 0, (h - gy) / s, np.where(s < 0, -gy / s, np.inf))
    return np.maximum(np.minimum(tx, ty), 0.0)


def _first_hits(flat: np.ndarray, n_along: int, n_across: int, ga: np.ndarray, gb: np.ndarray,
                ca: np.ndarray, cb: np.ndarray, u_lo: float, u_hi: np.ndarray,
                transpose: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """First occupied cell entered through a boundary a = const with u in [u_lo, u_hi).

    ``a`` is the axis whose boundaries are crossed (x, or y with ``transpose``), ``b`` the other.
    Returns the ray distance [cells] (inf: none) and the boundary's a-coordinate [cells].
    """
    m = ga.size
    inf = np.full(m, np.inf)
    abs_ca = np.abs(ca)
    moving = abs_ca > 1e-12
    base = np.where(ca > 0, np.floor(ga) + 1.0, np.floor(ga))  # first boundary crossed
    d0 = np.abs(base - ga)                                      # its distance along a [cells]
    with np.errstate(divide="ignore", invalid="ignore"):
        k_lo = np.where(moving, np.ceil(u_lo * abs_ca - d0), 0.0)
        k_hi = np.where(moving, np.ceil(u_hi * abs_ca - d0), 0.0)
    k_lo = np.maximum(k_lo, 0.0)
    count = np.maximum(k_hi - k_lo, 0.0).astype(np.int64)
    width = int(count.max(initial=0))
    if width == 0:
        return inf, np.zeros(m)
    k = k_lo[:, None] + np.arange(width)[None, :]
    valid = np.arange(width)[None, :] < count[:, None]
    step = np.where(ca > 0, 1.0, -1.0)[:, None]
    boundary = base[:, None] + step * k                          # a-coordinate of the boundary
    u = (d0[:, None] + k) / np.where(moving, abs_ca, 1.0)[:, None]
    cell_a = (boundary - (ca < 0)[:, None]).astype(np.int64)     # the cell entered
    cell_b = np.floor(gb[:, None] + u * cb[:, None]).astype(np.int64)
    valid &= (cell_a >= 0) & (cell_a < n_along) & (cell_b >= 0) & (cell_b < n_across)
    # Row-major (h, w): with ``transpose`` a = row and b = col, else a = col and b = row.
    index = cell_a * n_across + cell_b if transpose else cell_b * n_along + cell_a
    occ = np.zeros(valid.shape, dtype=bool)
    occ[valid] = flat[index[valid]]
    any_hit = occ.any(axis=1)
    first = np.argmax(occ, axis=1)
    rows = np.arange(m)
    u_hit = np.where(any_hit, u[rows, first], np.inf)
    return u_hit, np.where(any_hit, boundary[rows, first], 0.0)


@dataclass(frozen=True)
class Solid:
    """An obstacle as a prism from the floor (z = 0) to ``height`` [m]: a polygon (vertices in
    the map frame, (N, 2), N >= 3, closed implicitly) or a circle (``circle`` = (x, y, radius))."""

    height: float
    polygon: np.ndarray | None = None
    circle: tuple[float, float, float] | None = None
    name: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.height) and self.height > 0):
            raise WorldError(f"obstacle {self.name!r}: height must be > 0 m, got {self.height!r}")
        if (self.polygon is None) == (self.circle is None):
            raise WorldError(f"obstacle {self.name!r}: give exactly one of polygon or circle")
        if self.polygon is not None:
            poly = np.asarray(self.polygon, dtype=float)
            if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 3 \
                    or not np.isfinite(poly).all():
                raise WorldError(f"obstacle {self.name!r}: polygon must be >= 3 finite (x, y) "
                                 f"vertices")
            object.__setattr__(self, "polygon", poly)
        if self.circle is not None and not (all(math.isfinite(v) for v in self.circle)
                                            and self.circle[2] > 0):
            raise WorldError(f"obstacle {self.name!r}: circle must be finite (x, y, r > 0)")

    def segments(self) -> np.ndarray:
        """(N, 4) edges x1, y1, x2, y2 of a polygon solid."""
        assert self.polygon is not None
        p = self.polygon
        return np.hstack([p, np.roll(p, -1, axis=0)])


@dataclass(frozen=True, eq=False)
class Scene:
    """What the sensors see at one instant: the map (its walls extruded to ``wall_height``) and
    the solids (obstacles at that time). The occupancy mask is computed once per map."""

    grid: OccupancyGrid
    solids: tuple[Solid, ...] = ()
    wall_height: float = 2.0
    occupied_threshold: int = 50
    mask: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.wall_height) and self.wall_height > 0):
            raise WorldError(f"wall height must be > 0 m, got {self.wall_height!r}")
        if self.grid.origin[2] != 0.0:
            raise WorldError("sensors need a map whose origin yaw is 0; rotate the image instead")
        object.__setattr__(self, "solids", tuple(self.solids))
        object.__setattr__(self, "mask", self.grid.occupied(self.occupied_threshold))

    def with_solids(self, solids: Iterable[Solid]) -> Scene:
        """The same map (mask reused) with other obstacles, e.g. those at another time."""
        new = object.__new__(Scene)
        for name, value in (("grid", self.grid), ("solids", tuple(solids)),
                            ("wall_height", self.wall_height),
                            ("occupied_threshold", self.occupied_threshold),
                            ("mask", self.mask)):
            object.__setattr__(new, name, value)
        return new


def solids_taller_than(solids: Iterable[Solid], z: float) -> list[Solid]:
    """The solids a horizontal ray at height ``z`` [m] can hit."""
    return [s for s in solids if s.height > z]


def cast_solids(solids: Sequence[Solid], x0: np.ndarray | float, y0: np.ndarray | float,
                angles: np.ndarray) -> np.ndarray:
    """Distance [m] along each horizontal ray to the nearest solid's wall (inf: none); a ray that
    starts inside a circle or polygon hits at its exit (walls are surfaces, not volumes)."""
    angles = np.asarray(angles, dtype=float)
    c, s = np.cos(angles), np.sin(angles)
    px = np.broadcast_to(np.asarray(x0, dtype=float), angles.shape)
    py = np.broadcast_to(np.asarray(y0, dtype=float), angles.shape)
    best = np.full(angles.shape, np.inf)
    segs = [sol.segments() for sol in solids if sol.polygon is not None]
    if segs:
        best = np.minimum(best, ray_segments(px, py, c, s, np.vstack(segs)))
    circles = [sol.circle for sol in solids if sol.circle is not None]
    if circles:
        best = np.minimum(best, ray_circles(px, py, c, s, np.asarray(circles, dtype=float)))
    return best


def ray_segments(px: np.ndarray, py: np.ndarray, c: np.ndarray, s: np.ndarray,
                 segs: np.ndarray) -> np.ndarray:
    """Nearest t >= 0 where the ray p + t (c, s) meets one of the (N, 4) segments (inf: none)."""
    px, py, c, s = (a[..., None] for a in (px, py, c, s))
    ax, ay, bx, by = segs[:, 0], segs[:, 1], segs[:, 2], segs[:, 3]
    ex, ey = bx - ax, by - ay
    den = c * ey - s * ex
    wx, wy = ax - px, ay - py
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / den
        u = (wx * s - wy * c) / den
    ok = (np.abs(den) > 1e-12) & (t >= 0) & (u >= 0) & (u <= 1)
    return np.where(ok, t, np.inf).min(axis=-1)


def ray_circles(px: np.ndarray, py: np.ndarray, c: np.ndarray, s: np.ndarray,
                circles: np.ndarray) -> np.ndarray:
    """Nearest t >= 0 where the ray p + t (c, s) (unit direction) meets a circle's rim."""
    px, py, c, s = (a[..., None] for a in (px, py, c, s))
    ox, oy = px - circles[:, 0], py - circles[:, 1]
    b = ox * c + oy * s
    disc = b * b - (ox * ox + oy * oy - circles[:, 2] ** 2)
    root = np.sqrt(np.maximum(disc, 0.0))
    t1, t2 = -b - root, -b + root
    t = np.where(t1 >= 0, t1, t2)
    return np.where((disc >= 0) & (t >= 0), t, np.inf).min(axis=-1)
