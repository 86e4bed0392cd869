"""The distance-field ray caster against the reference: the chunked caster it replaced.

``reference_cast_grid`` below is lowerbase/world/raycast.py's ``cast_grid`` as it was before the
distance-field skipping (commit 17fa27f), kept verbatim as the oracle: it enumerates every cell
boundary crossing from the origin in growing distance chunks. The new caster must give the same
distances, faces and face coordinates, bit for bit, on random poses and angles in every shipped
map, with obstacles rasterised in, on dense lidar fans, and in the corner cases (axis-aligned
rays, origins on cell corners, off the grid, empty and full masks).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.errors import WorldError
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.maps import load_map
from lowerbase.world.obstacles import obstacles_from_dicts
from lowerbase.world.raycast import FACE_X, FACE_Y, GridField, GridHits, Scene, cast_grid

MAPS = ("warehouse", "corridor_loop", "empty_room")


# ---- the reference (verbatim but for the names) ----------------------------------------------

_REF_CHUNKS_CELLS = (16.0, 64.0, 256.0, 1024.0)  # chunk ends [cells]; the last one grows by x4


def reference_cast_grid(mask: np.ndarray, grid: OccupancyGrid, x0: np.ndarray | float,
                        y0: np.ndarray | float, angles: np.ndarray,
                        max_range: float | np.ndarray) -> GridHits:
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
    u_max = np.minimum(u_max, _ref_exit_distance(gx, gy, c, s, w, h))

    active = np.flatnonzero(~start_hit & (u_max > 0))
    lo = 0.0
    hi_iter = iter(_REF_CHUNKS_CELLS)
    hi = next(hi_iter)
    while active.size:
        ux, Xx = _ref_first_hits(flat, w, h, gx[active], gy[active], c[active], s[active],
                                 lo, np.minimum(hi, u_max[active]))
        uy, Yy = _ref_first_hits(flat, h, w, gy[active], gx[active], s[active], c[active],
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


def _ref_exit_distance(gx: np.ndarray, gy: np.ndarray, c: np.ndarray, s: np.ndarray, w: int,
                   h: int) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 0, (w - gx) / c, np.where(c < 0, -gx / c, np.inf))
        ty = np.where(s > 0, (h - gy) / s, np.where(s < 0, -gy / s, np.inf))
    return np.maximum(np.minimum(tx, ty), 0.0)


def _ref_first_hits(flat: np.ndarray, n_along: int, n_across: int, ga: np.ndarray, gb: np.ndarray,
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



# ---- the comparison ----------------------------------------------------------------------------


def assert_same(grid: OccupancyGrid, mask: np.ndarray, x: np.ndarray | float,
                y: np.ndarray | float, angles: np.ndarray, max_range: float | np.ndarray,
                grid_field: GridField | None = None) -> GridHits:
    new = cast_grid(mask, grid, x, y, angles, max_range, grid_field)
    ref = reference_cast_grid(mask, grid, x, y, angles, max_range)
    for name in ("distance", "face", "face_coord"):
        got, want = getattr(new, name), getattr(ref, name)
        assert got.shape == want.shape == np.shape(angles)
        bad = np.flatnonzero(got.ravel() != want.ravel())
        assert bad.size == 0, (name, bad[:5], got.ravel()[bad[:5]], want.ravel()[bad[:5]])
    return new


def random_rays(grid: OccupancyGrid, rng: np.random.Generator, n: int, off_grid: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origins uniform over the map (walls included) and ``off_grid`` m beyond, any heading."""
    h, w = grid.data.shape
    ox, oy = grid.origin[0], grid.origin[1]
    x = rng.uniform(ox - off_grid, ox + w * grid.resolution + off_grid, n)
    y = rng.uniform(oy - off_grid, oy + h * grid.resolution + off_grid, n)
    return x, y, rng.uniform(-math.pi, math.pi, n)


def free_poses(grid: OccupancyGrid, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` poses (x, y, yaw) at random points of free cells."""
    rows, cols = np.nonzero(grid.data == 0)
    pick = rng.integers(0, rows.size, n)
    x = grid.origin[0] + (cols[pick] + rng.random(n)) * grid.resolution
    y = grid.origin[1] + (rows[pick] + rng.random(n)) * grid.resolution
    return np.stack([x, y, rng.uniform(-math.pi, math.pi, n)], axis=1)


def with_obstacles(grid: OccupancyGrid, rng: np.random.Generator) -> OccupancyGrid:
    """``grid`` with a dozen random boxes and people rasterised in (Obstacles.merged)."""
    h, w = grid.data.shape
    span = np.array([w, h]) * grid.resolution
    specs: list[dict[str, object]] = []
    for i in range(12):
        centre = (rng.random(2) * span).tolist()
        if i % 3:
            specs.append({"kind": "box", "name": f"box{i}", "center": centre,
                          "size": rng.uniform(0.2, 2.0, 2).tolist(),
                          "yaw": float(rng.uniform(-math.pi, math.pi))})
        else:
            specs.append({"kind": "person", "name": f"p{i}", "path": [centre, centre]})
    return obstacles_from_dicts(specs).merged(grid, 0.0)


@pytest.mark.parametrize("name", MAPS)
def test_random_rays_anywhere_in_the_shipped_maps(name: str) -> None:
    grid = load_map(name)
    rng = np.random.default_rng(11)
    mask = grid.occupied()
    x, y, ang = random_rays(grid, rng, 6000, off_grid=1.0)
    hits = assert_same(grid, mask, x, y, ang, 40.0, Scene(grid).grid_field)
    assert np.isfinite(hits.distance).mean() > 0.5        # the rays do hit walls
    assert ((hits.face == FACE_X).any() and (hits.face == FACE_Y).any())
    # Per-ray limits, short ones included (the window ends at the limit, not a chunk's).
    limits = rng.uniform(0.0, 12.0, x.size)
    assert_same(grid, mask, x, y, ang, limits, Scene(grid).grid_field)


@pytest.mark.parametrize("name", MAPS)
def test_lidar_fans_from_free_poses_with_obstacles(name: str) -> None:
    rng = np.random.default_rng(5)
    grid = with_obstacles(load_map(name), rng)
    scene = Scene(grid)
    fan = np.radians(-137.5) + np.arange(1651) * math.radians(1.0 / 6.0)  # a nanoScan3
    for x, y, yaw in free_poses(grid, rng, 12):
        assert_same(grid, scene.mask, x, y, fan + yaw, 40.0, scene.grid_field)
    # Many poses at once, one ray each (as the camera's bins are cast: arrays of origins).
    x, y, ang = free_poses(grid, rng, 5000).T
    assert_same(grid, scene.mask, x, y, ang, 40.0, scene.grid_field)


def test_rays_along_the_axes_and_through_cell_corners() -> None:
    grid = load_map("warehouse")
    mask = grid.occupied()
    rng = np.random.default_rng(2)
    h, w = grid.data.shape
    # Origins on cell corners and on cell boundaries, rays along the axes, the diagonals and
    # at random angles: crossings of both axes at the same distance, boundaries at u = 0.
    cols, rows = rng.integers(0, w, 400), rng.integers(0, h, 400)
    corner_x, corner_y = cols * grid.resolution, rows * grid.resolution
    axes = np.arange(8) * (math.pi / 4)
    ang = np.concatenate([axes, axes + 1e-12, axes - 1e-12, rng.uniform(-4, 4, 8)])
    for x, y in ((corner_x, corner_y), (corner_x + 0.5 * grid.resolution, corner_y),
                 (corner_x + 0.3 * grid.resolution, corner_y + 0.7 * grid.resolution)):
        assert_same(grid, mask, x[:, None], y[:, None], np.broadcast_to(ang, (400, ang.size)),
                    30.0)


def test_empty_full_and_tiny_masks() -> None:
    rng = np.random.default_rng(3)
    for data in (np.zeros((40, 60), np.int8), np.full((40, 60), 100, np.int8),
                 np.zeros((1, 1), np.int8), np.full((1, 1), 100, np.int8)):
        grid = OccupancyGrid(data, 0.05, (-0.7, 0.4, 0.0))
        x, y, ang = random_rays(grid, rng, 2000, off_grid=0.5)
        hits = assert_same(grid, grid.occupied(), x, y, ang, 5.0)
        if not data.any():
            assert np.isinf(hits.distance).all()


def test_random_sparse_masks_and_resolutions() -> None:
    # Scattered single cells: many grazing rays and near misses, few long clear stretches.
    rng = np.random.default_rng(4)
    for density, res in ((0.002, 0.05), (0.02, 0.1), (0.2, 0.03)):
        data = np.where(rng.random((150, 230)) < density, 100, 0).astype(np.int8)
        grid = OccupancyGrid(data, res, (1.5, -2.0, 0.0))
        x, y, ang = random_rays(grid, rng, 4000, off_grid=0.3)
        assert_same(grid, grid.occupied(), x, y, ang, 100.0)


def test_the_scene_builds_its_field_once_and_checks_it() -> None:
    grid = load_map("empty_room")
    scene = Scene(grid)
    assert scene.with_solids(()).grid_field is scene.grid_field       # shared, built once
    other = OccupancyGrid(np.zeros((5, 5), np.int8), 0.05)
    with pytest.raises(WorldError, match="shape"):
        cast_grid(other.occupied(), other, 0.1, 0.1, np.zeros(3), 1.0, scene.grid_field)
    # Clearance is a lower bound: no occupied cell is closer to any point of a cell.
    fld = scene.grid_field
    h, w = fld.shape
    clear = fld.clearance.reshape(h + 2, w + 2)[1:-1, 1:-1]
    rows, cols = np.nonzero(scene.mask)
    rng = np.random.default_rng(6)
    for _ in range(200):
        r, c = rng.integers(0, h), rng.integers(0, w)
        px, py = c + rng.random(), r + rng.random()
        # Distance from the point to each occupied unit square.
        dx = np.maximum(np.maximum(cols - px, px - (cols + 1)), 0.0)
        dy = np.maximum(np.maximum(rows - py, py - (rows + 1)), 0.0)
        assert clear[r, c] <= np.hypot(dx, dy).min()
