"""Worlds, scans and drives for the localization tests (deterministic: seeds only).

Scans come from ``lowerbase.world.lidar`` (exact ray casting, seeded range noise).
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import LaserScan, Lidar, LidarConfig
from lowerbase.world.localization.poses import Pose2D, compose, inverse, wrap_scalar
from lowerbase.world.raycast import Scene

RES = 0.05


def grid_from_boxes(width_m: float, height_m: float,
                    boxes: list[tuple[float, float, float, float]]) -> OccupancyGrid:
    """A walled rectangle with filled boxes (x0, y0, x1, y1) [m]; origin at (0, 0)."""
    w, h = round(width_m / RES), round(height_m / RES)
    data = np.zeros((h, w), dtype=np.int8)
    data[:2, :] = data[-2:, :] = 100
    data[:, :2] = data[:, -2:] = 100
    for x0, y0, x1, y1 in boxes:
        data[round(y0 / RES):round(y1 / RES), round(x0 / RES):round(x1 / RES)] = 100
    return OccupancyGrid(data, RES)


def feature_room() -> OccupancyGrid:
    """12 x 8 m, with boxes and pillars placed without symmetry (and a corner block)."""
    return grid_from_boxes(12.0, 8.0, [(0.0, 6.5, 1.5, 8.0), (10.8, 7.0, 12.0, 8.0),
        (2.0, 5.5, 3.5, 6.0), (5.0, 1.0, 5.4, 2.6), (8.0, 4.5, 9.5, 5.2), (10.5, 1.0, 11.0, 1.4),
        (3.0, 2.0, 3.3, 2.3), (6.5, 6.6, 7.0, 8.0), (0.0, 3.8, 1.0, 4.1), (9.0, 2.5, 9.2, 2.7),
    ])


def corridor() -> OccupancyGrid:
    """A featureless corridor, 60 m x 2 m: its ends are far beyond a short lidar's range."""
    return grid_from_boxes(60.0, 2.0, [])


def cast(grid: OccupancyGrid, pose: Pose2D, beams: int = 360, range_max: float = 10.0,
         sigma: float = 0.01, rng: np.random.Generator | None = None) -> LaserScan:
    """A full-circle scan from ``pose`` by lowerbase.world.lidar (one lidar at the base
    origin), range noise ``sigma`` seeded from ``rng`` (none without it)."""
    config = LidarConfig(fov=2 * math.pi, angular_step=2 * math.pi / beams, range_max=range_max,
                         range_sigma=sigma if rng is not None else 0.0,
                         seed=int(rng.integers(2 ** 31)) if rng is not None else 0)
    scene = _SCENES.get(id(grid))
    if scene is None or scene.grid is not grid:
        scene = _SCENES[id(grid)] = Scene(grid)
    return Lidar(config).scan(scene, pose, 0.0)


_SCENES: dict[int, Scene] = {}


def path_poses(waypoints: list[Pose2D], speed: float = 0.5, dt: float = 0.1) -> list[Pose2D]:
    """Truth poses along straight legs between waypoints (turn in place at each one)."""
    out: list[Pose2D] = [waypoints[0]]
    for (x0, y0, _), (x1, y1, _) in itertools.pairwise(waypoints):
        heading = math.atan2(y1 - y0, x1 - x0)
        cur = out[-1]
        dyaw = wrap_scalar(heading - cur[2])
        turns = max(1, math.ceil(abs(dyaw) / (1.0 * dt)))
        out += [(cur[0], cur[1], wrap_scalar(cur[2] + dyaw * (i + 1) / turns))
                for i in range(turns)]
        dist = math.hypot(x1 - x0, y1 - y0)
        steps = max(1, math.ceil(dist / (speed * dt)))
        out += [(x0 + (x1 - x0) * (i + 1) / steps, y0 + (y1 - y0) * (i + 1) / steps, heading)
                for i in range(steps)]
    return out


def drifting_odometry(truth: list[Pose2D], scale: float = 1.02, yaw_rate_bias: float = 0.001,
                      teleports: tuple[int, ...] = ()) -> list[Pose2D]:
    """Odometry from the truth increments with a wheel-scale error and a heading bias per step
    [rad/step], starting at the origin of the odom frame (known, deterministic drift). At the
    indices in ``teleports`` the robot was carried: the wheels saw nothing."""
    odom: list[Pose2D] = [(0.0, 0.0, 0.0)]
    for i, (a, b) in enumerate(itertools.pairwise(truth)):
        if i + 1 in teleports:
            odom.append(odom[-1])
            continue
        dx, dy, dyaw = compose(inverse(a), b)
        moving = math.hypot(dx, dy) > 1e-9 or abs(dyaw) > 1e-9
        step = (dx * scale, dy * scale, dyaw * scale + (yaw_rate_bias if moving else 0.0))
        odom.append(compose(odom[-1], step))
    return odom


def pose_error(est: Pose2D, truth: Pose2D) -> tuple[float, float]:
    """(position error [m], |heading error| [rad])."""
    return (math.hypot(est[0] - truth[0], est[1] - truth[1]),
            abs(wrap_scalar(est[2] - truth[2])))


def in_free_space(grid: OccupancyGrid, poses: list[Pose2D], clearance: float = 0.3) -> bool:
    """True when every pose is at least ``clearance`` [m] from any occupied cell."""
    occ = np.argwhere(grid.data >= 50)
    cx, cy = grid.cell_to_world(occ[:, 1], occ[:, 0])
    return all(float(np.min(np.hypot(cx - x, cy - y))) >= clearance for x, y, _ in poses[::5])
