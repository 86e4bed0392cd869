"""The obstacle layer marks with the compiled mark_points and projects a scan with cached beam
directions: bit for bit what the numpy code before them gave (the marking's mask and cells, the
scan's points), on random points near, on and off the window, above and below the height
limits, on and beyond obstacle_range, and on scans with every kind of return."""

from __future__ import annotations

import math

import numpy as np

from lowerbase.navigation.costmap import SourceParams, scan_observation
from lowerbase.navigation.kernels import mark_points
from lowerbase.navigation.layers import LETHAL_OBSTACLE, Costmap2D, Observation, ObstacleLayer
from lowerbase.world.lidar import LaserScan


def mark_numpy(cm: Costmap2D, obs: Observation, max_height: float) -> None:
    """The marking of ObstacleLayer.update before the kernel."""
    p = obs.points
    top = min(obs.max_obstacle_height, max_height)
    d2 = ((p - np.asarray(obs.origin)) ** 2).sum(axis=1)
    keep = (p[:, 2] >= obs.min_obstacle_height) & (p[:, 2] <= top) \
        & (d2 < obs.obstacle_range ** 2)
    cols, rows = cm.world_to_map(p[keep, 0], p[keep, 1])
    ok = cm.inside(cols, rows)
    cm.data[rows[ok], cols[ok]] = LETHAL_OBSTACLE


def test_mark_points_marks_the_cells_numpy_marked() -> None:
    rng = np.random.default_rng(2121)
    for width, height, res, origin in ((100, 100, 0.05, (-2.5, -2.5)), (7, 40, 0.1, (1.3, -0.7)),
                                       (1, 1, 0.05, (0.0, 0.0))):
        for n in (0, 1, 50, 720):
            # on a dyadic grid: ox + r - ox == r for the points at obstacle_range below
            ox = origin[0] + float(rng.integers(-8, 8 + width)) * 0.125
            oy = origin[1] + float(rng.integers(-8, 8 + height)) * 0.125
            oz = float(rng.choice([0.0, 0.2]))
            span = max(width, height) * res
            pts = np.column_stack((ox + rng.uniform(-span, span, n),
                                   oy + rng.uniform(-span, span, n),
                                   rng.choice([0.0, 0.05, 0.5, 2.0, 2.5, -0.1], n)))
            # points exactly on cell boundaries and exactly at obstacle_range
            pts[: n // 5, 0] = origin[0] + rng.integers(-2, width + 2, n // 5) * res
            rng_m = float(rng.choice([0.5, 2.5, 100.0]))
            k = n // 10
            ang = rng.uniform(-math.pi, math.pi, k)
            pts[n // 5: n // 5 + k, 0] = ox + rng_m * np.cos(ang)
            pts[n // 5: n // 5 + k, 1] = oy + rng_m * np.sin(ang)
            pts[n // 5: n // 5 + k, 2] = oz
            if n >= 50:  # exactly at obstacle_range: not marked (d2 < range ** 2)
                pts[-4:] = [[ox + rng_m, oy, oz], [ox, oy - rng_m, oz],
                            [ox + 0.5 * rng_m, oy, oz], [ox, oy + 0.25 * rng_m, 2.0]]
            for max_height in (2.0, 0.3):
                obs = Observation((ox, oy, oz), pts, rng_m, 3.0, 0.0, 2.0)
                data = rng.choice(np.array([0, 100, 254, 255], np.uint8), size=(height, width))
                want = Costmap2D(width, height, res, origin)
                want.data = data.copy()
                mark_numpy(want, obs, max_height)
                got = Costmap2D(width, height, res, origin)
                got.data = data.copy()
                top = min(obs.max_obstacle_height, max_height)
                mark_points(got.data, pts[:, 0], pts[:, 1], pts[:, 2], ox, oy, oz,
                            obs.min_obstacle_height, top, obs.obstacle_range ** 2, origin[0],
                            origin[1], res, LETHAL_OBSTACLE)
                np.testing.assert_array_equal(got.data, want.data)


def test_obstacle_layer_marks_as_numpy_did() -> None:
    """The layer's whole update: clearing (unchanged) then the compiled marking, against the
    clearing then the numpy marking."""
    rng = np.random.default_rng(7)
    like = Costmap2D(100, 100, 0.05, (-2.5, -2.5))
    for _ in range(20):
        pts = np.column_stack((rng.uniform(-4, 4, 300), rng.uniform(-4, 4, 300),
                               rng.choice([0.0, 0.2, 3.0], 300)))
        obs = Observation((float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), 0.2), pts)
        got = ObstacleLayer(like)
        got.update([obs])
        want = ObstacleLayer(like)
        want.update([Observation(obs.origin, obs.points, obs.obstacle_range,
                                 obs.raytrace_range, obs.min_obstacle_height,
                                 obs.max_obstacle_height, marking=False)])
        mark_numpy(want.map, obs, want.max_obstacle_height)
        np.testing.assert_array_equal(got.map.data, want.map.data)
        assert (got.map.data == LETHAL_OBSTACLE).any()


def scan_points_numpy(scan: LaserScan, inf_is_valid: bool) -> np.ndarray:
    """scan_observation's points in base_link before the cached directions."""
    r = np.asarray(scan.ranges, float)
    if inf_is_valid:
        r = np.where(r == np.inf, scan.range_max - 1e-4, r)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
    a = scan.angles[ok]
    return np.column_stack((r[ok] * np.cos(a), r[ok] * np.sin(a), np.zeros(a.size)))


def test_scan_observation_points_are_the_per_scan_cosines() -> None:
    rng = np.random.default_rng(5)
    geometries = ((720, -math.pi, 2 * math.pi / 720), (1651, -2.4, math.radians(1 / 6)),
                  (3, 0.1, 0.5))
    for _ in range(10):
        for n, amin, inc in geometries:  # the cache changes geometry every scan here
            ranges = rng.uniform(0.0, 45.0, n).astype(np.float32)
            kinds = rng.integers(0, 7, n)
            ranges[kinds == 0] = np.inf
            ranges[kinds == 1] = -np.inf
            ranges[kinds == 2] = np.nan
            ranges[kinds == 3] = 0.01
            ranges[kinds == 4] = rng.choice([0.0625, 40.0], int((kinds == 4).sum()))  # limits
            scan = LaserScan("base_link", 1.0, amin, amin + (n - 1) * inc, inc, 0.0, 0.04,
                             0.0625, 40.0, ranges)
            pose = (float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5)),
                    float(rng.uniform(-4, 4)))
            for inf_is_valid in (False, True):
                src = SourceParams(inf_is_valid=inf_is_valid)
                obs = scan_observation(scan, pose, src)
                want = Observation((pose[0], pose[1], 0.0), np.empty((0, 3)))
                pts = scan_points_numpy(scan, inf_is_valid)
                x, y, yaw = pose
                c, s = math.cos(yaw), math.sin(yaw)
                ref = np.empty_like(pts)
                ref[:, 0] = x + c * pts[:, 0] - s * pts[:, 1]
                ref[:, 1] = y + s * pts[:, 0] + c * pts[:, 1]
                ref[:, 2] = pts[:, 2]
                np.testing.assert_array_equal(obs.points, ref)
                assert obs.origin == (want.origin[0], want.origin[1], 0.0)
