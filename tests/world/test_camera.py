"""Depth camera against closed forms: walls, the floor under pitch, boxes, ground removal, noise."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from lowerbase.errors import ConfigError, WorldError
from lowerbase.world.camera import CameraConfig, DepthCamera
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.raycast import Scene, Solid

RES = 0.05
IDEAL = CameraConfig(subpixel=0.0, x=0.0, y=0.0, pitch=0.0)


def empty(size: int = 400) -> OccupancyGrid:
    return OccupancyGrid(np.zeros((size, size), np.int8), RES, (-10.0, -10.0, 0.0))


def with_wall_at(x_wall: float) -> OccupancyGrid:
    """Occupied cells from x = x_wall [m] to 0.1 m further, across the whole map."""
    grid = empty()
    data = grid.data.copy()
    col = round((x_wall - grid.origin[0]) / RES)
    data[:, col:col + 2] = 100
    return OccupancyGrid(data, RES, grid.origin)


def heights(cfg: CameraConfig, points: np.ndarray, pose_z: float = 0.0) -> np.ndarray:
    """Height above the floor of optical-frame points (base at the origin, yaw 0)."""
    return pose_z + cfg.z + points.astype(float) @ cfg.optical_to_base()[2]


def test_depth_of_a_wall_at_known_distance() -> None:
    cfg = replace(IDEAL, z=0.3)
    frame = DepthCamera(cfg).render(Scene(with_wall_at(4.0), wall_height=2.0), (0.5, 0.0, 0.0),
                                    0.0)
    assert frame.depth.dtype == np.uint16 and frame.depth.shape == (480, 640)
    # Rows whose ray meets x = 4.0 between the floor and the wall top: depth = 3.5 m exactly.
    yo = (np.arange(480) - cfg.cy) / cfg.fy
    elevation = cfg.z - 3.5 * yo
    rows = (elevation > 0.01) & (elevation < 1.99)
    assert rows.sum() > 150 and (elevation > 2.01).sum() > 20
    np.testing.assert_array_equal(frame.depth[rows], 3500)
    # Above the wall top: nothing (0); below the floor line: the floor, nearer than the wall.
    assert np.all(frame.depth[elevation > 2.01] == 0)
    floor_rows = elevation < -0.01
    assert np.all((frame.depth[floor_rows] > 0) & (frame.depth[floor_rows] < 3500))
    # The cloud is in the optical frame: z forward = 3.5 on the wall, x right, y down.
    wall = frame.points[np.abs(frame.points[:, 2] - 3.5) < 1e-4]
    assert wall[:, 0].min() < -1.5 and wall[:, 0].max() > 1.5
    assert wall[:, 1].min() == pytest.approx(-1.7, abs=0.01)   # the wall top: 1.7 m above


@pytest.mark.parametrize("pitch_deg", [0.0, 15.0, 35.0])
def test_floor_depth_per_row_is_the_closed_form(pitch_deg: float) -> None:
    pitch = math.radians(pitch_deg)
    cfg = replace(IDEAL, z=0.42, pitch=pitch, max_range=12.0)
    frame = DepthCamera(cfg).render(Scene(empty()), (1.0, -2.0, 0.7), 0.0)
    yo = (np.arange(480) - cfg.cy) / cfg.fy
    down = math.sin(pitch) + yo * math.cos(pitch)   # metres of drop per metre of depth
    with np.errstate(divide="ignore"):
        expected = np.where(down > 0, cfg.z / down, np.inf)
    seen = (expected >= cfg.min_range) & (expected <= cfg.max_range)
    assert seen.sum() > 100
    got = frame.depth[seen].astype(float) / 1000.0
    np.testing.assert_allclose(got, np.broadcast_to(expected[seen, None], got.shape), atol=6e-4)
    assert np.all(frame.depth[~seen] == 0)
    assert frame.points_without_planes.shape[0] == 0   # nothing but floor
    assert frame.points.shape[0] == seen.sum() * 640


def test_box_cloud_has_the_box_height_and_ground_removal_keeps_only_it() -> None:
    cfg = replace(IDEAL, z=0.8, pitch=math.radians(30), max_range=8.0)
    box = Solid(0.5, polygon=np.array([[1.4, -0.3], [1.9, -0.3], [1.9, 0.3], [1.4, 0.3]]))
    scene = Scene(empty(), solids=(box,))
    frame = DepthCamera(cfg).render(scene, (0.0, 0.0, 0.0), 0.0)
    h = heights(cfg, frame.points)
    world = frame.points.astype(float) @ cfg.optical_to_base().T + [cfg.x, cfg.y, cfg.z]
    on_box = (world[:, 0] > 1.39) & (world[:, 0] < 1.91) & (np.abs(world[:, 1]) < 0.31) \
        & (h > 0.002)
    assert on_box.sum() > 1000
    assert h[on_box].max() == pytest.approx(0.5, abs=2e-3)
    top = np.abs(h[on_box] - 0.5) < 2e-3
    assert top.sum() > 500                         # the top face, seen from above
    assert h[on_box].min() < 0.05                  # the front face reaches the floor
    kept = heights(cfg, frame.points_without_planes)
    assert np.all(kept > cfg.ground_threshold)
    assert frame.points_without_planes.shape[0] == np.sum(h > cfg.ground_threshold)
    assert np.sum(np.abs(h) < 2e-3) > 10_000       # the floor is in points, not in the other
    # Colour marks the box (red-ish) where the cloud sees it.
    assert frame.color.shape == (480, 640, 3) and frame.color.dtype == np.uint8


def test_person_cylinder_is_seen_from_below_its_top() -> None:
    cfg = replace(IDEAL, z=0.3)
    person = Solid(1.7, circle=(3.0, 0.0, 0.25))
    frame = DepthCamera(cfg).render(Scene(empty(), solids=(person,)), (0.0, 0.0, 0.0), 0.0)
    # The optical axis meets the cylinder's front at x = 2.75 m.
    assert frame.depth[240, 320] == 2750 or frame.depth[239, 319] == 2750
    assert frame.depth[:, 320].max() == 2750


def test_depth_noise_is_quadratic_in_range_and_seeded() -> None:
    cfg = replace(IDEAL, z=0.3, subpixel=0.08, seed=9)
    scene = Scene(with_wall_at(3.0))
    yo = (np.arange(480) - cfg.cy) / cfg.fy
    elevation = cfg.z - 3.0 * yo
    rows = (elevation > 0.05) & (elevation < 1.95)
    camera = DepthCamera(cfg)
    depth = camera.render(scene, (0.0, 0.0, 0.0), 0.0).depth[rows].astype(float) / 1000.0
    sigma = 3.0 ** 2 * 0.08 / (cfg.fx * 0.05)   # 37 mm at 3 m
    err = (depth - 3.0).ravel()
    assert abs(err.mean()) < 4 * sigma / math.sqrt(err.size)
    assert err.std() == pytest.approx(math.hypot(sigma, 0.001 / math.sqrt(12)), rel=0.02)
    again = DepthCamera(cfg).render(scene, (0.0, 0.0, 0.0), 0.0).depth
    first = DepthCamera(cfg).render(scene, (0.0, 0.0, 0.0), 0.0).depth
    np.testing.assert_array_equal(again, first)
    assert not np.array_equal(camera.render(scene, (0.0, 0.0, 0.0), 0.1).depth, first)


def test_too_close_is_no_depth_and_mounting_errors_are_clear() -> None:
    cfg = replace(IDEAL, z=0.3, min_range=0.3)
    frame = DepthCamera(cfg).render(Scene(with_wall_at(0.2)), (0.0, 0.0, 0.0), 0.0)
    assert np.all(frame.depth[:200] == 0)   # the wall at 0.2 m is inside min_range
    with pytest.raises(WorldError, match=r"not below the wall height 0.25 m; mount it lower"):
        DepthCamera(cfg).render(Scene(empty(), wall_height=0.25), (0.0, 0.0, 0.0), 0.0)
    with pytest.raises(ConfigError, match=r"camera 'camera_1': pitch = 2.0 is invalid"):
        replace(IDEAL, pitch=2.0)
    with pytest.raises(ConfigError, match=r"width = 0 is invalid; allowed: an integer"):
        replace(IDEAL, width=0)
    with pytest.raises(ConfigError, match=r"max_range = 0.05 is invalid"):
        replace(IDEAL, max_range=0.05)
