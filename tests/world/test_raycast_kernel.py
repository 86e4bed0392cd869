"""The compiled grid ray caster (numba, lowerbase/world/raycast_kernel.py) against its numpy
reference (lowerbase/world/raycast_reference.py): the same distances, faces and face
coordinates, bit for bit, on random rays in every shipped map, lidar fans among obstacles,
random masks, and the edge cases (rays along cell boundaries and through corners, origins in
occupied cells and off the grid, ranges ending exactly on a crossing). Also: bad input is a
WorldError, and the kernel's cache works from many processes at once and is optional."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lowerbase.errors import WorldError
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.maps import load_map
from lowerbase.world.raycast import FACE_X, FACE_Y, GridField, GridHits, Scene, cast_grid
from lowerbase.world.raycast_reference import cast_grid_reference
from tests.world.test_raycast_equivalence import free_poses, random_rays, with_obstacles

MAPS = ("warehouse", "corridor_loop", "empty_room")
ROOT = Path(__file__).resolve().parents[2]


def assert_same(grid: OccupancyGrid, mask: np.ndarray, x: np.ndarray | float,
                y: np.ndarray | float, angles: np.ndarray, max_range: float | np.ndarray,
                grid_field: GridField | None = None) -> GridHits:
    fld = grid_field if grid_field is not None else GridField.from_mask(mask)
    new = cast_grid(mask, grid, x, y, angles, max_range, fld)
    ref = cast_grid_reference(mask, grid, x, y, angles, max_range, fld)
    for name in ("distance", "face", "face_coord"):
        got, want = getattr(new, name), getattr(ref, name)
        assert got.shape == want.shape == np.shape(angles)
        assert got.dtype == want.dtype
        bad = np.flatnonzero(got.ravel() != want.ravel())
        assert bad.size == 0, (name, bad[:5], got.ravel()[bad[:5]], want.ravel()[bad[:5]])
    return new


@pytest.mark.parametrize("name", MAPS)
def test_random_rays_in_the_shipped_maps(name: str) -> None:
    grid = load_map(name)
    scene = Scene(grid)
    rng = np.random.default_rng(21)
    x, y, ang = random_rays(grid, rng, 20000, off_grid=2.0)
    hits = assert_same(grid, scene.mask, x, y, ang, 40.0, scene.grid_field)
    assert (hits.distance == 0).any() and np.isinf(hits.distance).any()
    assert (hits.face == FACE_X).any() and (hits.face == FACE_Y).any()
    # Per-ray ranges, zero, negative and infinite ones included.
    limits = rng.uniform(-1.0, 15.0, x.size)
    limits[::97] = np.inf
    assert_same(grid, scene.mask, x, y, ang, limits, scene.grid_field)


@pytest.mark.parametrize("name", MAPS)
def test_lidar_fans_among_obstacles(name: str) -> None:
    rng = np.random.default_rng(8)
    grid = with_obstacles(load_map(name), rng)
    scene = Scene(grid)
    fan = np.radians(-137.5) + np.arange(1651) * math.radians(1.0 / 6.0)
    for x, y, yaw in free_poses(grid, rng, 10):
        assert_same(grid, scene.mask, x, y, fan + yaw, 40.0, scene.grid_field)
    x, y, ang = free_poses(grid, rng, 8000).T
    assert_same(grid, scene.mask, x, y, ang, 40.0, scene.grid_field)


def test_rays_along_boundaries_through_corners_and_from_occupied_cells() -> None:
    rng = np.random.default_rng(9)
    data = np.where(rng.random((60, 90)) < 0.05, 100, 0).astype(np.int8)
    data[20:23, 30:50] = 100                       # a wall to start inside of
    grid = OccupancyGrid(data, 0.1, (-2.0, 1.0, 0.0))
    mask = grid.occupied()
    cols, rows = rng.integers(-2, 93, 300), rng.integers(-2, 63, 300)
    cx, cy = grid.origin[0] + cols * 0.1, grid.origin[1] + rows * 0.1   # cell corners
    axes = np.arange(8) * (math.pi / 4)
    steep = np.arctan2([1, 2, 1, 3, 4], [2, 1, 3, 1, 3])    # through corners of other cells
    ang = np.concatenate([axes, axes + 1e-12, axes - 1e-12, steep, steep + math.pi,
                          rng.uniform(-4, 4, 6)])
    for x, y in ((cx, cy), (cx + 0.05, cy), (cx, cy + 0.03), (cx + 0.05, cy + 0.05)):
        hits = assert_same(grid, mask, x[:, None], y[:, None],
                           np.broadcast_to(ang, (x.size, ang.size)), 12.0)
    assert (hits.distance == 0).any()             # some origins are in occupied cells
    # Origins inside the wall: distance 0, no face.
    hits = assert_same(grid, mask, np.full(5, 1.5), np.full(5, 3.15), rng.uniform(-4, 4, 5), 5.0)
    assert (hits.distance == 0).all() and (hits.face == 0).all()


def test_ranges_ending_exactly_on_crossings_and_at_the_grid_edge() -> None:
    rng = np.random.default_rng(10)
    data = np.where(rng.random((50, 50)) < 0.03, 100, 0).astype(np.int8)
    grid = OccupancyGrid(data, 0.05)
    mask = grid.occupied()
    x, y, ang = random_rays(grid, rng, 3000)
    full = cast_grid_reference(mask, grid, x, y, ang, 10.0)
    hit = np.isfinite(full.distance) & (full.distance > 0)
    # The range is the hit's distance itself, a hair less or a hair more.
    d = full.distance[hit]
    for limit in (d, np.nextafter(d, 0.0), np.nextafter(d, np.inf), d - 0.025, d + 0.025):
        assert_same(grid, mask, x[hit], y[hit], ang[hit], limit)
    cut = assert_same(grid, mask, x[hit], y[hit], ang[hit], np.nextafter(d, 0.0))
    assert np.isinf(cut.distance).mean() > 0.5     # a cut before the hit cell sees nothing
    # Rays that leave the grid; a mask occupied right up to its edges.
    edge = np.zeros((30, 40), np.int8)
    edge[0, :] = edge[-1, :] = edge[:, 0] = edge[:, -1] = 100
    egrid = OccupancyGrid(edge, 0.05, (0.3, -0.2, 0.0))
    ex, ey, eang = random_rays(egrid, rng, 3000, off_grid=1.0)
    assert_same(egrid, egrid.occupied(), ex, ey, eang, 3.0)


@pytest.mark.parametrize("density,res", [(0.0, 0.05), (0.001, 0.05), (0.01, 0.02), (0.1, 0.1),
                                          (0.5, 0.05), (1.0, 0.05)])
def test_random_masks(density: float, res: float) -> None:
    rng = np.random.default_rng(int(density * 1000) + 1)
    data = np.where(rng.random((120, 170)) < density, 100, 0).astype(np.int8)
    grid = OccupancyGrid(data, res, (0.7, -1.3, 0.0))
    x, y, ang = random_rays(grid, rng, 5000, off_grid=0.5)
    assert_same(grid, grid.occupied(), x, y, ang, 200.0)
    for h, w in ((1, 1), (1, 7), (9, 1)):
        tiny = OccupancyGrid(np.where(rng.random((h, w)) < 0.5, 100, 0).astype(np.int8), res)
        tx, ty, tang = random_rays(tiny, rng, 500, off_grid=0.2)
        assert_same(tiny, tiny.occupied(), tx, ty, tang, 1.0)


def test_array_shapes_and_broadcast_origins() -> None:
    grid = load_map("empty_room")
    scene = Scene(grid)
    rng = np.random.default_rng(12)
    pose = free_poses(grid, rng, 1)[0]
    ang = rng.uniform(-4, 4, (7, 11))
    assert_same(grid, scene.mask, pose[0], pose[1], ang, 8.0, scene.grid_field)
    assert_same(grid, scene.mask, pose[0], pose[1], np.float64(0.3), 8.0, scene.grid_field)
    assert_same(grid, scene.mask, pose[0], pose[1], np.zeros(0), 8.0, scene.grid_field)


@pytest.mark.parametrize("x,y,ang,limit", [(math.nan, 1.0, 0.0, 5.0), (1.0, math.inf, 0.0, 5.0),
                                           (1.0, 1.0, math.nan, 5.0), (1.0, 1.0, 0.0, math.nan)])
def test_non_finite_rays_are_a_world_error(x: float, y: float, ang: float, limit: float) -> None:
    grid = load_map("empty_room")
    with pytest.raises(WorldError, match="finite"):
        cast_grid(grid.occupied(), grid, np.array([0.5, x]), y, np.array([0.1, ang]), limit)


_CHILD = """
import sys
import numpy as np
from lowerbase.world.maps import load_map
from lowerbase.world.raycast import Scene, cast_grid
from lowerbase.world.raycast_kernel import cast_rays
grid = load_map("warehouse")
scene = Scene(grid)
ang = np.linspace(-3.0, 3.0, 4001)
hits = cast_grid(scene.mask, grid, 6.0, 4.0, ang, 30.0, scene.grid_field)
sys.stdout.write(hits.distance.tobytes().hex() + " " + str(cast_rays._cache.__class__.__name__))
"""


def _children(n: int, env: dict[str, str]) -> list[str]:
    procs = [subprocess.Popen([sys.executable, "-c", _CHILD], cwd=ROOT, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(n)]
    outs = []
    for p in procs:
        out, err = p.communicate(timeout=600)
        assert p.returncode == 0, err[-2000:]
        outs.append(out)
    return outs


@pytest.mark.process
def test_the_cache_from_many_processes_at_once(tmp_path: Path) -> None:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    outs = _children(4, env)                       # an empty cache: all compile and write
    assert len(set(outs)) == 1 and outs[0].endswith(" FunctionCache")
    assert list(tmp_path.rglob("raycast_kernel.cast_rays-*.nbi"))
    assert not list(tmp_path.rglob("*.tmp.*"))     # written by atomic renames
    assert _children(2, env) == outs[:2]           # loaded from the cache


@pytest.mark.process
def test_no_writable_cache_location_compiles_in_memory() -> None:
    # No cache locator applies (as for a read-only install and home): numba refuses cache=True
    # when the kernel is defined; the module then compiles without a cache.
    env = dict(os.environ, NUMBA_CACHE_LOCATOR_CLASSES="IPythonCacheLocator")
    env.pop("NUMBA_CACHE_DIR", None)
    (out,) = _children(1, env)
    (want,) = _children(1, dict(os.environ))
    assert out.split()[0] == want.split()[0]
    assert out.endswith(" NullCache")
