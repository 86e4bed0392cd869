"""Lidar ray casting against closed-form rooms, REP-117 returns, noise, dropouts and merging."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from lowerbase.errors import ConfigError
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import Lidar, LidarConfig, LidarRig, MergedScanConfig
from lowerbase.world.raycast import Scene, Solid, cast_grid

RES = 0.05
IDEAL = LidarConfig(range_sigma=0.0, range_min=0.05, range_max=40.0)


def square_room(inner: float = 4.0, wall_cells: int = 2, margin: int = 4) -> OccupancyGrid:
    """A room whose free inside spans [0, inner] x [0, inner] [m], walls ``wall_cells`` thick."""
    n_in = round(inner / RES)
    n = n_in + 2 * (wall_cells + margin)
    data = np.zeros((n, n), np.int8)
    a, b = margin, margin + 2 * wall_cells + n_in
    data[a:b, a:b] = 100
    data[a + wall_cells:b - wall_cells, a + wall_cells:b - wall_cells] = 0
    off = -(margin + wall_cells) * RES
    return OccupancyGrid(data, RES, (off, off, 0.0))


def room_distance(x: float, y: float, angles: np.ndarray, inner: float = 4.0) -> np.ndarray:
    """Closed form: distance from (x, y) inside [0, inner]^2 to its walls along ``angles``."""
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (inner - x) / c, np.where(c < 0, -x / c, np.inf))
        ty = np.where(s > 0, (inner - y) / s, np.where(s < 0, -y / s, np.inf))
    return np.minimum(tx, ty)


def test_square_room_ranges_are_the_closed_form_distances() -> None:
    room = Scene(square_room())
    cfg = replace(IDEAL, x=0.3, y=-0.2, yaw=0.4)
    lidar = Lidar(cfg)
    pose = (1.37, 2.11, 0.9)
    scan = lidar.scan(room, pose, stamp=3.0)
    assert scan.ranges.size == 1651 and scan.ranges.dtype == np.float32
    assert scan.angle_increment == pytest.approx(math.radians(1 / 6))
    assert scan.angle_max == pytest.approx(math.radians(137.5), abs=1e-6)
    lx = pose[0] + math.cos(0.9) * 0.3 + math.sin(0.9) * 0.2
    ly = pose[1] + math.sin(0.9) * 0.3 - math.cos(0.9) * 0.2
    expected = room_distance(lx, ly, scan.angles + 0.9 + 0.4)
    np.testing.assert_allclose(scan.ranges, expected, rtol=1e-6, atol=1e-6)


def test_grid_cast_agrees_with_fine_sampling_and_a_wall_at_an_angle() -> None:
    # A straight wall at 30 deg, rasterised gap-free: every cell the line passes through.
    n = 200
    data = np.zeros((n, n), np.int8)
    p0, direction = np.array([1.0, 1.0]), np.array([math.cos(0.5236), math.sin(0.5236)])
    normal = np.array([-direction[1], direction[0]])
    for t in np.arange(0.0, 12.0, RES / 20):
        x, y = p0 + t * direction
        if 0 <= x < n * RES and 0 <= y < n * RES:
            data[int(y / RES), int(x / RES)] = 100
    grid = OccupancyGrid(data, RES)
    origin = np.array([5.0, 2.0])
    angles = np.linspace(1.2, 2.9, 400)  # all towards the wall, incidence <= 60 deg
    hits = cast_grid(grid.occupied(), grid, origin[0], origin[1], angles, 40.0).distance
    # Closed form to the geometric line: the hit is within the one-cell band around it.
    c, s = np.cos(angles), np.sin(angles)
    to_line = (p0 - origin) @ normal / (c * normal[0] + s * normal[1])
    perpendicular = np.abs((hits - to_line) * (c * normal[0] + s * normal[1]))
    assert np.all(perpendicular <= RES * math.sqrt(2))
    # An independent brute force: sample every RES/100 and take the first occupied cell.
    t = np.arange(0.0, 15.0, RES / 100)
    xs, ys = origin[0] + t[None, :] * c[:, None], origin[1] + t[None, :] * s[:, None]
    occ = data[(ys / RES).astype(int).clip(0, n - 1), (xs / RES).astype(int).clip(0, n - 1)] > 50
    sampled = t[np.argmax(occ, axis=1)]
    assert np.all(hits <= sampled + 1e-9)           # the exact cast never comes later
    # A corner cut shorter than the sampler's step is missed by it: it hits a cell later.
    assert np.all(sampled - hits <= RES * math.sqrt(2))
    assert np.mean(sampled - hits <= RES / 100 + 1e-9) > 0.97


def test_no_return_too_close_and_range_max_follow_rep117() -> None:
    room = Scene(square_room(inner=4.0))
    cfg = replace(IDEAL, fov=2 * math.pi, angular_step=math.radians(90), range_max=3.0,
                  range_min=0.5)
    lidar = Lidar(cfg)
    assert cfg.beams == 4
    # From (0.3, 3.5): beams -180, -90, 0, 90 deg see walls at 0.3, 3.5, 3.7, 0.5.
    scan = lidar.scan(room, (0.3, 3.5, 0.0), 0.0)
    assert scan.angle_min == pytest.approx(-math.pi)
    assert scan.ranges[0] == -np.inf          # 0.3 m < range_min: too close
    assert scan.ranges[1] == np.inf           # 3.5 m > range_max: no return
    assert scan.ranges[2] == np.inf
    assert scan.ranges[3] == pytest.approx(0.5)  # exactly range_min is a valid return
    empty = Scene(OccupancyGrid(np.zeros((50, 50), np.int8), RES))
    assert np.all(Lidar(cfg).scan(empty, (1.0, 1.0, 0.0), 0.0).ranges == np.inf)


def test_dropout_rate_and_seeded_noise_statistics() -> None:
    room = Scene(square_room(inner=4.0))
    cfg = replace(IDEAL, range_sigma=0.01, range_sigma_per_m=0.005, dropout_prob=0.1, seed=11)
    lidar = Lidar(cfg)
    pose = (2.0, 2.0, 0.0)
    true = lidar.true_ranges(room, pose)
    np.testing.assert_allclose(true, room_distance(2.0, 2.0, cfg.angles), atol=1e-9)
    scans = np.array([lidar.scan(room, pose, k * 0.04).ranges for k in range(60)], float)
    dropped = np.isnan(scans)
    n = dropped.size
    assert abs(dropped.mean() - 0.1) < 4 * math.sqrt(0.1 * 0.9 / n)
    z = (scans - true)[~dropped] / (0.01 + 0.005 * np.broadcast_to(true, scans.shape)[~dropped])
    assert abs(z.mean()) < 4 / math.sqrt(z.size)
    assert abs(z.std() - 1.0) < 0.02
    again = Lidar(cfg)
    np.testing.assert_array_equal(again.scan(room, pose, 0.0).ranges, scans[0])
    other = Lidar(replace(cfg, seed=12)).scan(room, pose, 0.0).ranges
    assert not np.array_equal(other, scans[0], equal_nan=True)


def box_distance(angles: np.ndarray, lo: tuple[float, float], hi: tuple[float, float]
                 ) -> np.ndarray:
    """Closed form (slab method) from the origin to an axis-aligned box outside it."""
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1x, t2x = lo[0] / c, hi[0] / c
        t1y, t2y = lo[1] / s, hi[1] / s
    t_in = np.maximum(np.minimum(t1x, t2x), np.minimum(t1y, t2y))
    t_out = np.minimum(np.maximum(t1x, t2x), np.maximum(t1y, t2y))
    return np.where((t_in <= t_out) & (t_in >= 0), t_in, np.inf)


def test_front_and_back_lidars_merge_into_the_geometric_nearest_return() -> None:
    room = Scene(square_room(inner=4.0))
    box = Solid(0.5, polygon=np.array([[2.9, 1.7], [3.3, 1.7], [3.3, 2.1], [2.9, 2.1]]))
    low = Solid(0.1, circle=(1.0, 1.0, 0.2))  # below the scan planes: not seen
    scene = room.with_solids([box, low])
    front = replace(IDEAL, name="front", frame_id="laser_front", x=0.34, y=0.24,
                    yaw=math.radians(45))
    back = replace(IDEAL, name="back", frame_id="laser_back", x=-0.34, y=-0.24,
                   yaw=math.radians(-135), seed=2)
    rig = LidarRig([front, back], MergedScanConfig())
    pose = (2.0, 2.0, 0.0)  # base at the room centre, axes aligned
    scan = rig.scan(scene, pose, stamp=1.5)
    assert scan.frame_id == "base_link" and scan.ranges.size == 720
    assert scan.angle_increment == pytest.approx(2 * math.pi / 720)
    assert scan.range_max == pytest.approx(40.0 + math.hypot(0.34, 0.24))
    assert np.isfinite(scan.ranges).all()   # the two 275 deg lidars cover the full circle
    angles = scan.angles
    expected = np.minimum(room_distance(2.0, 2.0, angles),
                          box_distance(angles, (0.9, -0.3), (1.3, 0.1)))
    # Each bin holds the nearest return within +-half a bin: it can only be nearer than the
    # bin centre's distance by the surface's slope across half a bin (45 deg corners: x1).
    half = scan.angle_increment / 2
    worst = np.minimum(
        np.minimum(room_distance(2.0, 2.0, angles - half), room_distance(2.0, 2.0, angles + half)),
        np.minimum(box_distance(angles - half, (0.9, -0.3), (1.3, 0.1)),
                   box_distance(angles + half, (0.9, -0.3), (1.3, 0.1))))
    lower = np.minimum(expected, worst) - 1e-5
    assert np.all(scan.ranges >= lower)
    assert np.all(scan.ranges <= expected + 1e-5)
    # The box face at x = 0.9 m is seen straight ahead; the low circle is not seen.
    assert scan.ranges[360] == pytest.approx(0.9, abs=1e-5)
    toward_low = np.argmin(np.abs(angles - math.atan2(-1.0, -1.0)))
    assert scan.ranges[toward_low] == pytest.approx(2 * math.sqrt(2), abs=0.03)


def test_merge_marks_uncovered_and_dropped_bins_nan() -> None:
    room = Scene(square_room())
    only_front = replace(IDEAL, fov=math.radians(90), angular_step=math.radians(0.25))
    scan = LidarRig([only_front]).scan(room, (2.0, 2.0, 0.0), 0.0)
    angles = scan.angles
    ahead = np.abs(angles) < math.radians(44)
    behind = np.abs(angles) > math.radians(46)
    assert np.isfinite(scan.ranges[ahead]).all()
    assert np.isnan(scan.ranges[behind]).all()
    blind = replace(only_front, dropout_prob=0.999999, seed=5)
    assert np.isnan(LidarRig([blind]).scan(room, (2.0, 2.0, 0.0), 0.0).ranges).all()


@pytest.mark.parametrize(("change", "message"), [
    ({"range_max": 0.01}, r"range_max = 0.01 is invalid"),
    ({"fov": 0.0}, r"fov = 0.0 is invalid"),
    ({"angular_step": float("nan")}, r"angular_step = nan is invalid"),
    ({"dropout_prob": 1.0}, r"dropout_prob = 1 leaves no measurement"),
    ({"rate_hz": -5.0}, r"rate_hz = -5.0 is invalid"),
    ({"seed": -1}, r"seed = -1 must be an integer"),
    ({"angular_step": 1e-7}, r"beams; allowed: 1..100000"),
])
def test_bad_lidar_config_is_one_config_error(change: dict[str, float], message: str) -> None:
    with pytest.raises(ConfigError, match=message) as info:
        replace(IDEAL, **change)
    assert "\n" not in str(info.value)
