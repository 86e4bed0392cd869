"""Exact 2D ray casting, vectorised over rays: the shared core of the lidar and the depth camera.

Grid: a ray enters a new cell exactly where it crosses a vertical (x = const) or horizontal
(y = const) cell boundary. The crossings are enumerated in closed form, the cell entered at each
is looked up in the occupancy mask (``np.take``), and the first occupied one gives the hit: the
distance is exact (floating point) to the boundary of the first occupied cell the ray passes
through, corner cuts included. Only the stretches near walls are enumerated: a distance field
(scipy's Euclidean distance transform of the mask, made a lower bound on the clearance of every
point of a cell) lets each ray skip, sphere-tracing style, any stretch that cannot meet an
occupied cell; the crossings are enumerated in short windows where the clearance is small, and
rays that have hit (or left the grid) drop out. Skipping never changes a result: the crossings
and their distances are computed by the same closed-form expressions from the ray's origin.

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

_SKIP_MIN = 2.0      # [cells] a ray skips ahead when its clearance is at least this ...
_WINDOW = 8.0        # [cells] ... else enumerates the crossings of the next window this long,
_WINDOW_MAX = 96.0   # doubling on each miss in a row (a ray grazing a wall) up to this
_SKIP_STEPS = 10     # skips per round at most (the last few rays converge slowly)
_MARGIN = 0.01       # [cells] taken off the clearance: floating point and float32 rounding


@dataclass(frozen=True)
class GridHits:
    """Per-ray result of :func:`cast_grid` (arrays of the rays' shape)."""

    distance: np.ndarray  # [m]; inf = nothing occupied within max_range
    face: np.ndarray      # FACE_* of the boundary hit
    face_coord: np.ndarray  # [m] the boundary's x (FACE_X) or y (FACE_Y) in the map frame


@dataclass(frozen=True, eq=False)
class GridField:
    """An occupancy mask prepared for :func:`cast_grid`, built once per map.

    ``occupied`` is the mask padded with one free cell on every side, flattened; ``clearance``
    (same layout, float32, cells) is a lower bound on the distance from any point of the cell
    to any occupied cell: the distance transform between cell centres less sqrt(2) (half a
    diagonal at each end) and a margin; 0 on the padding ring, where points off the grid are
    clamped.
    """

    shape: tuple[int, int]
    occupied: np.ndarray
    clearance: np.ndarray

    @classmethod
    def from_mask(cls, mask: np.ndarray) -> GridField:
        from scipy.ndimage import distance_transform_edt

        mask = np.asarray(mask, dtype=bool)
        if mask.ndim != 2:
            raise WorldError(f"an occupancy mask must be 2D, got shape {mask.shape}")
        h, w = mask.shape
        padded = np.zeros((h + 2, w + 2), dtype=bool)
        padded[1:-1, 1:-1] = mask
        if padded.any():
            edt = distance_transform_edt(~padded)
            clear = np.maximum(edt - (math.sqrt(2.0) + _MARGIN), 0.0).astype(np.float32)
        else:  # nothing to hit: any step up to the grid's far corner is safe
            clear = np.full(padded.shape, float(h + w + 4), dtype=np.float32)
        clear[0, :] = clear[-1, :] = clear[:, 0] = clear[:, -1] = 0.0
        return cls((h, w), padded.ravel(), clear.ravel())


def cast_grid(mask: np.ndarray, grid: OccupancyGrid, x0: np.ndarray | float,
              y0: np.ndarray | float, angles: np.ndarray, max_range: float | np.ndarray,
              grid_field: GridField | None = None) -> GridHits:
    """Cast rays from (x0, y0) [m, map frame] at ``angles`` [rad] against ``mask`` (bool, the
    grid's shape, True = occupied). Cells outside the grid are free. ``grid_field`` is the
    mask's :class:`GridField` if the caller keeps one (:attr:`Scene.grid_field`), else it is
    built here (a distance transform of the whole mask). The rays are cast by the compiled
    kernel (:mod:`raycast_kernel`), bit for bit as the numpy reference
    (:func:`raycast_reference.cast_grid_reference`) casts them."""
    return cast_rays_prepared(grid, prepare_rays(mask, grid, x0, y0, angles, max_range,
                                                 grid_field))


def cast_rays_prepared(grid: OccupancyGrid, rays: Rays) -> GridHits:
    """:func:`cast_grid` of rays already in grid cells (:func:`prepare_rays`, or a caller that
    builds the same :class:`Rays` with the same expressions: :class:`~lowerbase.world.lidar.
    LidarRig`)."""
    from lowerbase.world.raycast_kernel import cast_rays

    fld, n = rays.field, rays.c.size
    dist, face, coord = np.empty(n), np.empty(n, dtype=np.int8), np.empty(n)
    h, w = fld.shape
    cast_rays(fld.occupied, fld.clearance, h, w, rays.gx, rays.gy, rays.c, rays.s, rays.u_max,
              float(grid.origin[0]), float(grid.origin[1]), float(grid.resolution), _SKIP_MIN,
              _WINDOW, _WINDOW_MAX, _SKIP_STEPS, dist, face, coord)
    return GridHits(dist.reshape(rays.shape), face.reshape(rays.shape),
                    coord.reshape(rays.shape))


@dataclass(frozen=True)
class Rays:
    """:func:`cast_grid`'s input in grid cells: the flat arrays both casters take."""

    field: GridField
    shape: tuple[int, ...]
    gx: np.ndarray     # origins [cells, from the grid's origin]
    gy: np.ndarray
    c: np.ndarray      # unit directions
    s: np.ndarray
    u_max: np.ndarray  # ranges [cells]


def prepare_rays(mask: np.ndarray, grid: OccupancyGrid, x0: np.ndarray | float,
                 y0: np.ndarray | float, angles: np.ndarray, max_range: float | np.ndarray,
                 grid_field: GridField | None) -> Rays:
    """Check :func:`cast_grid`'s arguments and convert them to grid cells (:class:`Rays`)."""
    if grid.origin[2] != 0.0:
        raise WorldError("sensors need a map whose origin yaw is 0; rotate the map image instead")
    fld = GridField.from_mask(mask) if grid_field is None else grid_field
    if fld.shape != np.shape(mask):
        raise WorldError(f"the grid field's shape {fld.shape} is not the mask's "
                         f"{np.shape(mask)}")
    angles = np.asarray(angles, dtype=float)
    shape = angles.shape
    ang = angles.ravel()
    res = grid.resolution
    gx = np.broadcast_to((np.asarray(x0, dtype=float) - grid.origin[0]) / res, shape).ravel()
    gy = np.broadcast_to((np.asarray(y0, dtype=float) - grid.origin[1]) / res, shape).ravel()
    u_max = np.broadcast_to(np.asarray(max_range, dtype=float) / res, shape).ravel()
    if not (np.isfinite(gx).all() and np.isfinite(gy).all() and np.isfinite(ang).all()
            and not np.isnan(u_max).any()):
        raise WorldError("ray casting needs finite origins and angles and non-NaN ranges")
    # Fresh writable arrays: numba compiles (and caches) one kernel per array type.
    return Rays(fld, shape, np.array(gx), np.array(gy), np.cos(ang), np.sin(ang),
                np.array(u_max))


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
    the solids (obstacles at that time). The occupancy mask is computed once per map, and its
    :class:`GridField` on first use (shared by :meth:`with_solids`)."""

    grid: OccupancyGrid
    solids: tuple[Solid, ...] = ()
    wall_height: float = 2.0
    occupied_threshold: int = 50
    mask: np.ndarray = field(init=False, repr=False)
    _fields: list[GridField] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.wall_height) and self.wall_height > 0):
            raise WorldError(f"wall height must be > 0 m, got {self.wall_height!r}")
        if self.grid.origin[2] != 0.0:
            raise WorldError("sensors need a map whose origin yaw is 0; rotate the image instead")
        object.__setattr__(self, "solids", tuple(self.solids))
        object.__setattr__(self, "mask", self.grid.occupied(self.occupied_threshold))
        object.__setattr__(self, "_fields", [])

    @property
    def grid_field(self) -> GridField:
        """The mask prepared for :func:`cast_grid` (a distance transform: built once)."""
        if not self._fields:
            self._fields.append(GridField.from_mask(self.mask))
        return self._fields[0]

    def with_solids(self, solids: Iterable[Solid]) -> Scene:
        """The same map (mask reused) with other obstacles, e.g. those at another time."""
        new = object.__new__(Scene)
        for name, value in (("grid", self.grid), ("solids", tuple(solids)),
                            ("wall_height", self.wall_height),
                            ("occupied_threshold", self.occupied_threshold),
                            ("mask", self.mask), ("_fields", self._fields)):
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
