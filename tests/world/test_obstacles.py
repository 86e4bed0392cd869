"""Obstacles: closed-form positions of walking people, box geometry, rasterisation against an
independent cell/shape distance test, scenario tables and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.errors import WorldError
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.obstacles import Box, Obstacles, Person, obstacles_from_dicts


def free_grid(n: int = 20, res: float = 0.1) -> OccupancyGrid:
    return OccupancyGrid(np.zeros((n, n), np.int8), res)


def test_person_walks_the_polyline_then_stops() -> None:
    p = Person("p", ((0, 0), (4, 0), (4, 3)), speed=1.0, start=2.0)
    expected = {0.0: (0, 0), 2.0: (0, 0), 5.0: (3, 0), 8.0: (4, 2), 9.0: (4, 3), 100.0: (4, 3)}
    for t, xy in expected.items():
        assert p.position_at(t) == pytest.approx(xy), t


def test_looping_person_closes_the_path() -> None:
    p = Person("p", ((0, 0), (4, 0), (4, 3)), speed=1.0, start=2.0, loop=True)
    # 4 + 3 + 5 = 12 m a lap; 9.5 m in, 2.5 m along the closing leg (4, 3) -> (0, 0)
    assert p.position_at(2.0 + 9.5) == pytest.approx((2.0, 1.5))
    assert p.position_at(2.0 + 12.0 + 3.0) == pytest.approx((3.0, 0.0))
    assert p.position_at(2.0 + 5 * 12.0) == pytest.approx((0.0, 0.0))


def test_obstacles_are_a_pure_function_of_time() -> None:
    def make() -> Obstacles:
        return Obstacles([Person("walker", ((1, 1), (5, 1), (5, 4)), speed=0.7, loop=True),
                          Box("crate", (2, 2), (1, 0.5))])

    later_first = make()
    [later_first.shapes_at(t) for t in (50.0, 3.0, 1e4)]
    fresh = make()
    for t in (0.0, 1.3, 7.7):
        for (n1, s1), (n2, s2) in zip(later_first.shapes_at(t), fresh.shapes_at(t), strict=True):
            assert n1 == n2 and s1.equals_exact(s2, 0.0)


def test_standing_person_and_circle_accuracy() -> None:
    p = Person("still", ((2.0, 3.0),), speed=1.0, radius=0.25)
    assert p.position_at(1e6) == (2.0, 3.0)
    assert p.prism_at(5.0).circle == (2.0, 3.0, 0.25)
    # a regular 64-gon inscribed in the circle (0.16 % less area, 0.3 mm less radius at worst)
    assert p.shape_at(0.0).area == pytest.approx(32 * 0.25 ** 2 * math.sin(2 * math.pi / 64))


def test_box_corners() -> None:
    box = Box("b", (1.0, 2.0), (0.6, 0.2), yaw=math.pi / 2, height=0.8)
    # turned by 90 degrees: 0.2 m along x, 0.6 m along y
    assert box.shape_at(0.0).bounds == pytest.approx((0.9, 1.7, 1.1, 2.3))
    assert box.shape_at(0.0).area == pytest.approx(0.12)
    prism = box.prism_at(0.0)
    assert prism.height == 0.8 and prism.polygon is not None and prism.polygon.shape == (4, 2)


def test_box_overlay_cells() -> None:
    grid = free_grid()
    # edges on cell boundaries: x 0.8..1.2, y 0.9..1.1 -> 4 x 2 cells, neighbours only touched
    overlay = Obstacles([Box("b", (1.0, 1.0), (0.4, 0.2))]).overlay(grid, 0.0)
    rows, cols = np.nonzero(overlay.data == 100)
    assert sorted(set(cols.tolist())) == [8, 9, 10, 11] and sorted(set(rows.tolist())) == [9, 10]
    assert (overlay.data == 100).sum() == 8 and set(np.unique(overlay.data)) == {0, 100}
    # shifted by half a cell: partly covered cells count, 5 x 3
    shifted = Obstacles([Box("b", (1.05, 1.05), (0.4, 0.2))]).overlay(grid, 0.0)
    assert (shifted.data == 100).sum() == 15


def test_person_overlay_against_cell_distance() -> None:
    grid = OccupancyGrid(np.zeros((60, 60), np.int8), 0.05, (-1.0, -1.0, 0.0))
    person = Person("p", ((0.0, 0.0), (1.0, 0.5)), speed=0.5, radius=0.3)
    t = 1.3
    cx, cy = person.position_at(t)
    marked = Obstacles([person]).overlay(grid, t).data == 100
    # independent: a cell overlaps the disc iff its nearest point is closer than r
    col, row = np.meshgrid(np.arange(60), np.arange(60))
    x0, y0 = -1.0 + col * 0.05, -1.0 + row * 0.05
    dx = np.clip(cx, x0, x0 + 0.05) - cx
    dy = np.clip(cy, y0, y0 + 0.05) - cy
    dist = np.hypot(dx, dy)
    clear = np.abs(dist - 0.3) > 0.002  # away from the polygon's 0.3 mm approximation
    assert np.array_equal(marked[clear], (dist < 0.3)[clear])
    assert marked.sum() > 100


def test_heights_and_merged() -> None:
    grid = free_grid()
    grid.data[0, :] = -1
    obstacles = Obstacles([Box("low", (1.0, 1.0), (0.4, 0.4), height=0.5),
                           Box("tall", (1.2, 1.0), (0.4, 0.4), height=2.0),
                           Box("edge", (0.5, 0.0), (0.2, 0.2))])
    heights = obstacles.heights(grid, 0.0)
    assert heights[9, 8] == 0.5 and heights[9, 10] == 2.0 and heights[9, 12] == 2.0
    assert heights[15, 15] == 0.0
    merged = obstacles.merged(grid, 0.0)
    assert merged.data[9, 8] == 100 and merged.data[0, 15] == -1 and merged.data[0, 5] == 100
    assert grid.data[9, 8] == 0  # the map itself is untouched


def test_from_dicts() -> None:
    obstacles = obstacles_from_dicts([
        {"kind": "box", "name": "crate", "center": [1, 2], "size": [0.6, 0.4], "height": 0.5},
        {"kind": "person", "name": "walker", "path": [[0, 0], [3, 0]], "speed": 1.5,
         "loop": True},
    ])
    assert len(obstacles) == 2
    assert [n for n, _ in obstacles.shapes_at(0.0)] == ["crate", "walker"]
    assert obstacles.items[1].position_at(1.0) == pytest.approx((1.5, 0.0))


@pytest.mark.parametrize(("spec", "needle"), [
    ({"kind": "tree", "name": "t"}, "kind must be box or person, got 'tree'"),
    ({"kind": "box", "name": "b", "center": [0, 0], "size": [1, 1], "colour": "red"},
     "unknown field(s) colour (a box has center, height, name, size, yaw)"),
    ({"kind": "box", "name": "b", "size": [1, 1]}, "missing 1 required positional argument"),
    ({"kind": "box", "name": "b", "center": [0, 0], "size": [1, -1]}, "size must be > 0 m"),
    ({"kind": "box", "name": "b", "center": [0, float("nan")], "size": [1, 1]},
     "center must be a finite number"),
    ({"kind": "box", "name": "b", "center": [0], "size": [1, 1]}, "center must be [x, y]"),
    ({"kind": "box", "name": "", "center": [0, 0], "size": [1, 1]}, "non-empty name"),
    ({"kind": "box", "name": "b", "center": [0, 0], "size": [1, 1], "height": 0},
     "height must be a finite number > 0"),
    ({"kind": "person", "name": "p", "path": []}, "path must be a list of [x, y] points"),
    ({"kind": "person", "name": "p", "path": [[0, 0]], "loop": True},
     "a looping path needs two distinct points"),
    ({"kind": "person", "name": "p", "path": [[0, 0], [1, 0]], "speed": -1},
     "speed must be >= 0 m/s"),
    ({"kind": "person", "name": "p", "path": [[0, 0], [1, 0]], "loop": "yes"},
     "loop must be true or false"),
    ({"kind": "person", "name": "p", "path": [[0, 0], [1, 0]], "radius": "wide"},
     "radius must be a number"),
])
def test_bad_obstacles_one_line(spec: dict[str, object], needle: str) -> None:
    with pytest.raises(WorldError) as err:
        obstacles_from_dicts([spec])
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_duplicate_names_and_bad_time() -> None:
    with pytest.raises(WorldError, match="crate used twice"):
        Obstacles([Box("crate", (0, 0), (1, 1)), Box("crate", (2, 2), (1, 1))])
    with pytest.raises(WorldError, match="time must be finite"):
        Person("p", ((0, 0), (1, 1))).position_at(float("nan"))
