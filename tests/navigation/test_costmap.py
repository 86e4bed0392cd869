"""Costmaps (costmap_2d's conventions) checked against closed forms: inflation costs, footprint
radii, marking and clearing from the world's own lidars, the rolling window, set_footprint,
enable_costmaps, clear_costmaps and the footprint cost."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from skimage import draw

from lowerbase.errors import WorldError
from lowerbase.navigation.costmap import (
    CostmapParams,
    SourceParams,
    camera_cloud,
    global_costmap,
    local_costmap,
)
from lowerbase.navigation.layers import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    InflationParams,
    StaticParams,
    footprint_radii,
    line_cells,
)
from lowerbase.world.camera import CameraConfig
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, Footprint
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import LaserScan, LidarConfig, LidarRig, MergedScanConfig
from lowerbase.world.raycast import Scene, Solid

RES = 0.05
INSCRIBED = 0.4           # the seed's footprint padded by 0.1: its sides at y = +-0.4
CIRCUMSCRIBED = math.hypot(0.5, 0.353)


def expected_cost(d_cells: float, inscribed: float = INSCRIBED, radius: float = 0.55,
                  k: float = 10.0) -> int:
    """costmap_2d's InflationLayer::computeCost, written out independently."""
    if d_cells == 0:
        return 254
    if d_cells > math.ceil(radius / RES - 1e-9):
        return 0
    d = d_cells * RES
    if d <= inscribed:
        return 253
    return int(252 * math.exp(-k * (d - inscribed)))


def grid_with(cells: list[tuple[int, int]], shape: tuple[int, int] = (41, 41),
              value: int = 100) -> OccupancyGrid:
    data = np.zeros(shape, np.int8)
    for r, c in cells:
        data[r, c] = value
    return OccupancyGrid(data, RES)


def one_beam(r: float, angle: float = 0.0) -> LaserScan:
    return LaserScan("base_link", 0.0, angle, angle, 0.01, 0.0, 0.04, 0.05, 40.0,
                     np.array([r], np.float32))


# ---------------------------------------------------------------------------- inflation

def test_inflation_of_one_lethal_cell_is_the_closed_form_everywhere() -> None:
    cm = global_costmap(grid_with([(20, 20)]))
    costs = cm.costs
    rows, cols = np.indices(costs.shape)
    want = np.array([[expected_cost(math.hypot(r - 20, c - 20)) for c in range(41)]
                     for r in range(41)])
    assert (costs == want).all()
    # a few by hand: 252 e^-0.5 = 152.8, 252 e^-1.5 = 56.2, the radius is 11 cells
    assert costs[20, 20] == 254 and costs[20, 28] == 253 and costs[28, 20] == 253
    assert costs[20, 29] == 152 and costs[20, 31] == 56 and costs[20, 32] == 0
    assert costs[27, 27] == int(252 * math.exp(-10 * (RES * math.hypot(7, 7) - 0.4)))
    assert ((costs > 0) == (np.hypot(rows - 20, cols - 20) <= 11)).all()


def test_inflation_from_a_wall_and_its_parameters() -> None:
    data = np.zeros((30, 60), np.int8)
    data[:, 30] = 100
    params = CostmapParams(inflation=InflationParams(inflation_radius=1.0,
                                                     cost_scaling_factor=3.0))
    costs = global_costmap(OccupancyGrid(data, RES), params).costs
    for k in range(0, 30):
        want = expected_cost(k, radius=1.0, k=3.0)
        assert costs[15, 30 + k] == want and costs[15, 30 - k] == want, k
    assert (costs == costs[:1]).all()            # the same on every row


def test_unknown_space_tracked_and_inflated_only_within_the_inscribed_radius() -> None:
    grid = grid_with([(20, 20)])
    grid.data[20, 24] = -1          # 0.2 m from the wall cell: inside the inscribed radius
    grid.data[20, 35] = -1          # 0.75 m: beyond the inflation radius
    grid.data[20, 30] = -1          # 0.5 m: in the decaying band, stays unknown
    costs = global_costmap(grid).costs
    assert costs[20, 24] == INSCRIBED_INFLATED_OBSTACLE
    assert costs[20, 30] == NO_INFORMATION and costs[20, 35] == NO_INFORMATION
    blind = global_costmap(grid, CostmapParams(
        static=StaticParams(track_unknown_space=False))).costs
    assert blind[20, 35] == 0 and blind[20, 30] == expected_cost(10)
    both = global_costmap(grid, CostmapParams(
        inflation=InflationParams(inflate_unknown=True))).costs
    assert both[20, 30] == expected_cost(10)


def test_radii_of_the_seeds_footprint_padded_by_0_1() -> None:
    cm = global_costmap(grid_with([]))
    assert cm.inscribed_radius == pytest.approx(INSCRIBED, abs=1e-12)
    assert cm.circumscribed_radius == pytest.approx(CIRCUMSCRIBED, abs=1e-12)
    assert footprint_radii(DEFAULT_FOOTPRINT) == pytest.approx((0.3, math.hypot(0.4, 0.253)))
    # a diamond: the nearest point of its edges lies mid-edge, 1/sqrt(2) away
    diamond = Footprint(((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)))
    assert footprint_radii(diamond) == pytest.approx((math.sqrt(0.5), 1.0))
    assert cm.circumscribed_cost == int(252 * math.exp(-10 * (CIRCUMSCRIBED - INSCRIBED)))


# ---------------------------------------------------------------------------- marking and clearing

def room(inner: float = 6.0) -> OccupancyGrid:
    n = round(inner / RES) + 8
    data = np.zeros((n, n), np.int8)
    data[:4, :] = data[-4:, :] = data[:, :4] = data[:, -4:] = 100
    return OccupancyGrid(data, RES)


def rig() -> LidarRig:
    ideal = LidarConfig(range_sigma=0.0)
    return LidarRig([replace(ideal, name="front", frame_id="f", x=0.34, y=0.24,
                             yaw=math.radians(45)),
                     replace(ideal, name="back", frame_id="b", x=-0.34, y=-0.24,
                             yaw=math.radians(-135), seed=2)], MergedScanConfig())


BOX = Solid(1.0, polygon=np.array([[4.0, 3.0], [4.5, 3.0], [4.5, 3.6], [4.0, 3.6]]))


def test_a_box_seen_by_the_lidars_is_marked_and_cleared_when_it_is_gone() -> None:
    grid, pose = room(), (2.5, 3.3, 0.0)
    cm = local_costmap(grid, pose)
    cm.update(pose, scan=rig().scan(Scene(grid).with_solids([BOX]), pose, 0.0))
    layer = cm.obstacle_layer
    assert layer is not None
    # the returns (float32 ranges) end a hair short of the face x = 4.0: the cells [3.95, 4.0)
    face = [cm.world_to_map(4.0 - 0.01, y) for y in np.arange(3.025, 3.6, 0.05)]
    assert all(layer.map.data[r, c] == LETHAL_OBSTACLE for c, r in face)
    assert cm.cost_at(3.99, 3.3) == LETHAL_OBSTACLE
    # free on the way there, and nothing marked beyond obstacle_range (2.5 m): the walls
    c0, r = cm.world_to_map(2.5 + 0.45, 3.3)
    c1, _ = cm.world_to_map(3.95, 3.3)
    assert (layer.map.data[r, c0:c1] == 0).all()
    cols, rows = np.nonzero(layer.map.data.T == LETHAL_OBSTACLE)
    xs, ys = cm.map_to_world(cols, rows)
    assert (np.hypot(xs - 2.5, ys - 3.3) < 2.5 + RES).all()
    cm.update(pose, scan=rig().scan(Scene(grid), pose, 0.04))     # the box taken away
    assert all(layer.map.data[r, c] == 0 for c, r in face)
    assert cm.cost_at(3.99, 3.3) == 0


def test_clearing_stops_at_raytrace_range_and_at_the_hit() -> None:
    pose = (2.0, 2.0, 0.0)
    cm = local_costmap(None, pose, CostmapParams(width=5.0, height=5.0, static_map=False,
                                                 scan=SourceParams(raytrace_range=1.0)))
    layer = cm.obstacle_layer
    assert layer is not None

    def at(x: float) -> int:
        c, r = cm.world_to_map(x, 2.0)
        return int(layer.map.data[r, c])
    cm.update(pose, scan=one_beam(1.525))           # marks x = 3.525
    cm.update(pose, scan=one_beam(0.625))           # marks x = 2.625
    assert at(3.525) == LETHAL_OBSTACLE and at(2.625) == LETHAL_OBSTACLE
    cm.update(pose, scan=one_beam(2.025))           # clears only the first 1.0 m ...
    assert at(2.625) == 0 and at(3.525) == LETHAL_OBSTACLE   # ... so 3.525 stays
    assert at(4.025) == LETHAL_OBSTACLE
    cm.update(pose, scan=one_beam(0.725))           # a nearer hit clears nothing behind it
    assert at(2.725) == LETHAL_OBSTACLE and at(3.525) == LETHAL_OBSTACLE
    assert at(4.025) == LETHAL_OBSTACLE
    assert (layer.map.data == LETHAL_OBSTACLE).sum() == 3
    cm.update(pose, scan=one_beam(0.325))           # under the padded footprint: cleared
    assert at(2.325) == 0 and (layer.map.data == LETHAL_OBSTACLE).sum() == 3
    # obstacle_range (2.5 m): a return at 2.6 m clears but does not mark
    diag = math.sqrt(0.5)
    for r, want in ((2.45, LETHAL_OBSTACLE), (2.55, 0)):
        cm.update(pose, scan=one_beam(r, angle=math.pi / 4))
        c, row = cm.world_to_map(2.0 + r * diag, 2.0 + r * diag)
        assert layer.map.data[row, c] == want


def test_line_cells_are_bresenhams() -> None:
    """Batched lines equal skimage.draw.line (Bresenham) except where the ideal line passes
    exactly half-way between two cells, where either is right."""
    rng = np.random.default_rng(7)
    ends = rng.integers(-40, 41, size=(300, 2))
    cols, rows = line_cells(0, 0, ends[:, 0], ends[:, 1])
    n = np.maximum(np.abs(ends[:, 0]), np.abs(ends[:, 1]))
    starts = np.concatenate(([0], np.cumsum(n + 1)))
    assert cols.size == starts[-1]
    for i, (c, r) in enumerate(ends):
        got = set(zip(cols[starts[i]:starts[i + 1]].tolist(),
                      rows[starts[i]:starts[i + 1]].tolist(), strict=True))
        rr, cc = draw.line(0, 0, int(r), int(c))
        want = set(zip(cc.tolist(), rr.tolist(), strict=True))
        assert len(got) == len(want) == n[i] + 1 and (0, 0) in got and (c, r) in got
        for gc, gr in got ^ want:        # only ties: half a cell off the ideal line
            off = abs(gr - gc * r / c) if abs(c) >= abs(r) else abs(gc - gr * c / r)
            assert off == pytest.approx(0.5), (c, r, gc, gr)


def test_cloud_marking_respects_the_height_limits() -> None:
    pose = (2.0, 2.0, math.pi / 2)
    cm = local_costmap(room(), pose, CostmapParams(
        width=5.0, height=5.0, static_map=False,
        cloud=SourceParams(min_obstacle_height=0.05, max_obstacle_height=1.0)))
    pts = np.array([[1.0, 0.0, 0.5], [1.0, 0.5, 1.5], [1.0, -0.5, 0.02], [1.2, 0.0, np.nan]])
    cm.update(pose, cloud=(pts, (0.35, 0.0, 0.3)))
    # base x = map +y at yaw 90 deg: (1, 0) -> (2, 3); (1, 0.5) -> (1.5, 3); (1, -0.5) -> (2.5, 3)
    assert cm.cost_at(2.0, 3.0) == LETHAL_OBSTACLE
    assert cm.cost_at(1.5 + 0.01, 3.0 + 0.01) < INSCRIBED_INFLATED_OBSTACLE
    assert cm.cost_at(2.5 + 0.01, 3.0 + 0.01) < INSCRIBED_INFLATED_OBSTACLE


def test_camera_cloud_is_in_base_link() -> None:
    cam = CameraConfig()
    pts, origin = camera_cloud(np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                               cam)
    p = cam.pitch
    assert origin == (0.35, 0.0, 0.30)
    assert pts[0] == pytest.approx([0.35 + 2 * math.cos(p), 0.0, 0.30 - 2 * math.sin(p)])
    assert pts[1] == pytest.approx([0.35, -1.0, 0.30])           # optical x = right
    assert pts[2] == pytest.approx([0.35 - math.sin(p), 0.0, 0.30 - math.cos(p)])  # y = down


# ---------------------------------------------------------------------------- rolling window

def test_rolling_window_follows_the_robot_and_keeps_obstacles_in_world_coordinates() -> None:
    grid = room(20.0)
    pose = (5.0, 5.0, 0.0)
    cm = local_costmap(grid, pose)
    assert cm.costs.shape == (100, 100)
    cm.update(pose, scan=one_beam(1.0))                 # marks (6.0, 5.0)
    assert cm.cost_at(6.01, 5.01) == LETHAL_OBSTACLE
    for x, y in ((5.3, 5.1), (6.7, 6.2), (4.1, 3.3)):
        cm.update((x, y, 0.0))
        ox, oy = cm.origin
        assert ox + 2.5 - RES <= x <= ox + 2.5 + RES and oy + 2.5 - RES <= y <= oy + 2.5 + RES
        assert ((ox - grid.origin[0]) / RES) == pytest.approx(round((ox - grid.origin[0]) / RES))
        assert cm.cost_at(6.01, 5.01) == LETHAL_OBSTACLE
        assert (cm.costs == LETHAL_OBSTACLE).sum() == 1
    cm.update((12.0, 12.0, 0.0))                        # the mark leaves the window ...
    assert (cm.costs == LETHAL_OBSTACLE).sum() == 0
    cm.update(pose)                                     # ... and is forgotten, as costmap_2d
    assert cm.cost_at(6.01, 5.01) == 0


def test_local_costmap_with_the_static_map_shows_the_walls() -> None:
    grid = room(6.0)
    cm = local_costmap(grid, (1.0, 1.0, 0.0), CostmapParams(width=5.0, height=5.0))
    assert cm.cost_at(0.1, 1.0) == LETHAL_OBSTACLE               # the west wall
    # beyond the map: the obstacle layer (track_unknown_space false) knows it free, as in
    # costmap_2d's updateWithMax; with it tracking unknown space, it stays NO_INFORMATION
    assert cm.cost_at(-0.6, 1.0) == 0
    tracked = local_costmap(grid, (1.0, 1.0, 0.0), CostmapParams(
        width=5.0, height=5.0, track_unknown_space=True))
    assert tracked.cost_at(-0.6, 1.0) == NO_INFORMATION
    assert tracked.cost_at(1.0, 1.0) == 0                        # known free on the map


# ---------------------------------------------------------------------------- services

def test_set_footprint_changes_the_inflation_and_a_bad_one_changes_nothing() -> None:
    cm = global_costmap(grid_with([(20, 20)]))
    assert cm.costs[20, 29] == 152
    big = [(-0.6, 0.5, 0.0), (0.6, 0.5, 0.0), (0.6, -0.5, 0.0), (-0.6, -0.5, 0.0)]
    cm.set_footprint(big)
    assert cm.inscribed_radius == pytest.approx(0.6) and cm.circumscribed_radius == \
        pytest.approx(math.hypot(0.7, 0.6))
    assert cm.costs[20, 29] == INSCRIBED_INFLATED_OBSTACLE        # 0.45 m < 0.6 m
    assert cm.costs[20, 31] == INSCRIBED_INFLATED_OBSTACLE
    before = cm.costs.copy()
    for bad in ([(0, 0), (1, 1)], [(-1, -1), (1, 1), (1, -1), (-1, 1)], [(1, 1), (2, 1), (2, 2)],
                [(0.1, "x"), (1, 1), (0, 1)]):
        with pytest.raises(WorldError) as err:
            cm.set_footprint(bad)  # type: ignore[arg-type]
        assert "\n" not in str(err.value) and "set_footprint" in str(err.value)
    assert (cm.costs == before).all() and cm.inscribed_radius == pytest.approx(0.6)


def test_enable_costmaps_false_stops_marking_and_true_resumes() -> None:
    pose = (2.0, 2.0, 0.0)
    cm = local_costmap(None, pose)
    cm.update(pose, scan=one_beam(1.0))
    assert cm.cost_at(3.01, 2.01) == LETHAL_OBSTACLE
    assert cm.enable(False) == (True, "costmap updates disabled")
    assert cm.cost_at(3.01, 2.01) == 0                 # the layer is left out ...
    cm.update(pose, scan=one_beam(1.0, angle=math.pi / 2))
    assert cm.cost_at(2.01, 3.01) == 0 and cm.stats.ignored_disabled == 1
    cm.enable(True)
    assert cm.cost_at(3.01, 2.01) == LETHAL_OBSTACLE   # ... and comes back, not the ignored one
    assert cm.cost_at(2.01, 3.01) == 0
    cm.update(pose, scan=one_beam(1.0, angle=math.pi / 2))
    assert cm.cost_at(2.01, 3.01) == LETHAL_OBSTACLE


def test_clear_costmaps_resets_the_obstacles_not_the_map() -> None:
    grid = room(6.0)
    pose = (1.0, 1.0, 0.0)
    cm = local_costmap(grid, pose, CostmapParams(width=5.0, height=5.0))
    cm.update(pose, scan=one_beam(1.0))
    assert cm.cost_at(2.01, 1.01) == LETHAL_OBSTACLE
    cm.clear()
    assert cm.cost_at(2.01, 1.01) == 0 and cm.cost_at(0.1, 1.0) == LETHAL_OBSTACLE


def test_footprint_cost_touching_a_wall_is_lethal_and_free_space_is_zero() -> None:
    data = np.zeros((80, 120), np.int8)
    data[:, 100] = 100                                  # a wall at x in [5.00, 5.05)
    cm = global_costmap(OccupancyGrid(data, RES))
    # padded half-length 0.5 m: the front edge at x = 4.52 + 0.5 reaches into the wall cell
    assert cm.footprint_cost((4.52, 2.0, 0.0)) == LETHAL_OBSTACLE
    assert cm.footprint_cost((2.0, 2.0, 0.3)) == 0
    # 0.1 m short of the wall: inside the inflation, below LETHAL
    assert 0 < cm.footprint_cost((4.4, 2.0, 0.0)) < LETHAL_OBSTACLE
    assert cm.footprint_cost((0.2, 2.0, 0.0)) == LETHAL_OBSTACLE          # off the map
    # turned 90 deg the half-length along x is 0.4 m: free again at 4.5 (0.1 m gap + inflation)
    assert cm.footprint_cost((4.52, 2.0, math.pi / 2)) < LETHAL_OBSTACLE


def test_bad_poses_are_one_line_errors() -> None:
    cm = local_costmap(None, (0.0, 0.0, 0.0))
    for bad in ((math.nan, 0.0, 0.0), (0.0, 0.0)):
        with pytest.raises(WorldError):
            cm.update(bad)
        with pytest.raises(WorldError):
            cm.footprint_cost(bad)
