"""The footprint: validation, padding, and contact against walls, the map's edge and obstacles,
checked against closed-form areas and an independent supersampled estimate."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from lowerbase.errors import WorldError
from lowerbase.world.footprint import (
    DEFAULT_FOOTPRINT,
    Footprint,
    contact,
    validate_pose,
)
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.maps import load_map
from lowerbase.world.obstacles import Box, Obstacles, Person

SEED = "[[-0.400, 0.253], [-0.353, 0.3], [0.353, 0.3], [0.4, 0.253], [0.4, -0.253], " \
       "[0.353, -0.3], [-0.353, -0.3], [-0.4, -0.253]]"
#: 0.8 x 0.6 m minus four corner triangles with 0.047 m legs
AREA = 0.8 * 0.6 - 4 * 0.5 * 0.047 ** 2


def wall_grid(col: int = 30) -> OccupancyGrid:
    """2 x 2 m at 0.05 m, free, one wall column (x in [col*0.05, col*0.05 + 0.05))."""
    data = np.zeros((40, 40), np.int8)
    data[:, col] = 100
    return OccupancyGrid(data, 0.05)


def test_default_is_the_seeds_polygon() -> None:
    assert Footprint.parse(SEED) == DEFAULT_FOOTPRINT
    assert DEFAULT_FOOTPRINT.polygon.area == pytest.approx(AREA, abs=1e-12)
    assert DEFAULT_FOOTPRINT.polygon.bounds == (-0.4, -0.3, 0.4, 0.3)
    assert DEFAULT_FOOTPRINT.radius == pytest.approx(math.hypot(0.4, 0.253))


def test_padding_as_costmap_2d() -> None:
    padded = DEFAULT_FOOTPRINT.padded(0.1)
    assert np.allclose(padded.points[:2], ((-0.5, 0.353), (-0.453, 0.4)))
    assert padded.polygon.bounds == pytest.approx((-0.5, -0.4, 0.5, 0.4))
    # a vertex on an axis moves along that axis only
    assert Footprint(((0.5, 0.0), (0.0, 0.5), (-0.5, 0.0), (0.0, -0.5))).padded(0.1).points \
        == ((0.6, 0.0), (0.0, 0.6), (-0.6, 0.0), (0.0, -0.6))


@pytest.mark.parametrize(("points", "needle"), [
    (((0, 0), (1, 1)), "at least 3 points"),
    (((-1, -1), (1, 1), (1, -1), (-1, 1)), "simple polygon"),            # a bow tie
    (((1, 1), (2, 1), (2, 2), (1, 2)), "surround the robot's origin"),
    (((-1, -1), (1, float("nan")), (0, 1)), "must be finite"),
    (((-1, -1), (1, -1), (-1, -1)), "simple polygon"),                   # no area
    ((("a", 1), (1, 1), (0, 1)), "list of [x, y] points"),
])
def test_bad_footprints(points: tuple[tuple[float, float], ...], needle: str) -> None:
    with pytest.raises(WorldError) as err:
        Footprint(points)
    assert needle in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("text", ["[[0, 1], [1]]", "hello", "[[0, 1], [1, 0], [", "{}"])
def test_bad_footprint_text(text: str) -> None:
    with pytest.raises(WorldError, match=r"written \[\[x1, y1\]"):
        Footprint.parse(text)


def test_contact_with_a_wall_closed_form() -> None:
    grid = wall_grid()  # the wall's face is at x = 1.5
    assert contact((1.0, 1.0, 0.0), grid) is None
    assert contact((1.1, 1.0, 0.0), grid) is None           # front edge exactly on the face
    hit = contact((1.12, 1.0, 0.0), grid)
    assert hit is not None and hit.touched == ("wall",)
    # the front 2 cm: half-width 0.3 - (x - 0.353) on the chamfer, 0.38 <= x <= 0.4
    assert hit.area == pytest.approx(0.02 * 2 * (0.3 - (0.39 - 0.353)), rel=1e-9)
    assert hit.point[1] == pytest.approx(1.0) and 1.5 < hit.point[0] < 1.51
    # turned by 90 degrees the robot is 0.3 m long in x: touching from 1.2 + 0.3 = 1.5 on
    assert contact((1.2, 1.0, math.pi / 2), grid) is None
    assert contact((1.21, 1.0, math.pi / 2), grid) is not None


def test_threshold_and_unknown_cells() -> None:
    grid = wall_grid()
    for value, touches in ((-1, False), (49, False), (50, True), (100, True)):
        grid.data[:, 30] = value
        assert (contact((1.2, 1.0, 0.0), grid) is not None) == touches, value


def test_map_edge_closed_form() -> None:
    grid = OccupancyGrid(np.zeros((40, 40), np.int8), 0.05, (-0.3, -1.0, 0.0))
    hit = contact((0.0, 0.0, 0.0), grid)  # the rear 0.1 m is beyond x = -0.3
    assert hit is not None and hit.touched == ("map_edge",)
    rear = 2 * (0.047 * 0.653 + ((-0.353) ** 2 - 0.4 ** 2) / 2 + 0.3 * 0.053)
    assert hit.area == pytest.approx(rear, rel=1e-9)
    assert contact((0.1, 0.0, 0.0), grid) is None


def supersampled_wall_area(pose: tuple[float, float, float], grid: OccupancyGrid,
                           step: float = 0.004) -> float:
    """Independent estimate: lattice points inside the footprint on occupied cells."""
    poly = DEFAULT_FOOTPRINT.at(pose)
    minx, miny, maxx, maxy = poly.bounds
    xs, ys = np.meshgrid(np.arange(minx + step / 2, maxx, step),
                         np.arange(miny + step / 2, maxy, step))
    inside = shapely.contains_xy(poly, xs, ys)
    col, row = grid.world_to_cell(xs[inside], ys[inside])
    ok = grid.inside(col, row)
    return float((grid.data[row[ok], col[ok]] >= 50).sum() * step * step)


def test_contact_area_matches_a_supersampled_estimate_on_the_warehouse() -> None:
    grid = load_map("warehouse")
    rng = np.random.default_rng(3)
    touched = 0
    for _ in range(60):
        pose = (rng.uniform(7.0, 18.0), rng.uniform(2.5, 9.5), rng.uniform(-math.pi, math.pi))
        estimate = supersampled_wall_area(pose, grid)
        hit = contact(pose, grid)
        area = 0.0 if hit is None else hit.area
        assert area == pytest.approx(estimate, abs=2e-3), pose
        touched += hit is not None
    assert 10 < touched < 50  # the poses cover both cases


def test_validate_pose() -> None:
    grid = wall_grid()
    assert validate_pose([1.0, 1.0, 0.0], grid) == (1.0, 1.0, 0.0)
    for bad in ((float("nan"), 1.0, 0.0), (1.0, 1.0, float("inf"))):
        with pytest.raises(WorldError, match="pose must be finite numbers"):
            validate_pose(bad, grid)
    with pytest.raises(WorldError, match=r"a pose is \(x, y, yaw\) numbers"):
        validate_pose((1.0, 2.0), grid)
    with pytest.raises(WorldError) as err:
        validate_pose((1.5, 1.0, 0.0), grid)
    assert str(err.value) == ("the robot at (1.500, 1.000, yaw 0.000) would touch wall near "
                              "(1.52, 1.00): place it on free floor")
    with pytest.raises(WorldError, match="rotated origin"):
        validate_pose((1.0, 1.0, 0.0), OccupancyGrid(grid.data, 0.05, (0.0, 0.0, 0.1)))


def test_contact_with_obstacles() -> None:
    grid = wall_grid(col=39)
    crate = Box("crate", (1.5, 1.0), (0.4, 0.4))   # x 1.3..1.7, y 0.8..1.2
    walker = Person("walker", ((0.6, 0.2), (0.6, 1.8)), speed=0.5, radius=0.2)
    obstacles = Obstacles([crate, walker])
    # the robot's front (x = 1.4) is 0.1 m into the crate over its whole 0.4 m width
    hit = contact((1.0, 1.0, 0.0), grid, obstacles, t=0.0)
    assert hit is not None and hit.touched == ("crate",)
    assert hit.area == pytest.approx(0.1 * 0.4)
    assert hit.point == pytest.approx((1.35, 1.0))
    # the walker starts 0.8 m below the robot's centre and reaches it at t = 1.6 s
    away = (0.6, 1.0, 0.0)
    assert contact(away, grid, obstacles, t=0.0) is None
    late = contact(away, grid, obstacles, t=1.6)
    assert late is not None and late.touched == ("walker",)
    # the person's disc (r 0.2) enters the footprint's y = 0.7 edge at y_c = 0.5
    assert contact(away, grid, obstacles, t=0.59) is None
    assert contact(away, grid, obstacles, t=0.61) is not None
    # wall and obstacle together, in that order, with the areas added
    # (the front 0.05 m in the wall at x = 1.95, the rear 0.1 m in the box's x 0.9..1.3)
    wall_only = contact((1.6, 1.0, 0.0), grid)
    both = contact((1.6, 1.0, 0.0), grid, Obstacles([Box("c", (1.1, 1.0), (0.4, 0.4))]))
    assert wall_only is not None and wall_only.touched == ("wall",)
    assert wall_only.area == pytest.approx(2 * (0.3 * 0.003 + 0.653 * 0.047
                                                - (0.4 ** 2 - 0.353 ** 2) / 2))
    assert both is not None and both.touched == ("wall", "c")
    assert both.area == pytest.approx(wall_only.area + 0.1 * 0.4)


def test_validate_pose_names_the_obstacle() -> None:
    obstacles = Obstacles([Box("pallet", (1.0, 1.0), (1.2, 0.8))])
    with pytest.raises(WorldError, match=r"would touch pallet near \(1.00, 1.00\)"):
        validate_pose((1.0, 1.0, 0.3), wall_grid(), obstacles)
    # the same pose is fine without the pallet, or for a robot small enough to fit on it
    assert validate_pose((1.0, 1.0, 0.3), wall_grid()) == (1.0, 1.0, 0.3)
    tiny = Footprint(((-0.01, -0.01), (0.01, -0.01), (0.0, 0.01)))
    with pytest.raises(WorldError, match="would touch pallet"):
        validate_pose((1.0, 1.0, 0.3), wall_grid(), obstacles, footprint=tiny)
    assert validate_pose((0.3, 0.3, 0.0), wall_grid(), obstacles, footprint=tiny)
