"""Navigator.set_footprint(points, which): the public API behind the set_footprint topics.
Each costmap takes its own footprint; the global one is also the footprint the planner and the
controller check. Checked against costmap_2d's radii of the padded polygon (computed here) and
the planner's answers next to a wall."""

from __future__ import annotations

import math

import pytest

from lowerbase.errors import WorldError
from lowerbase.navigation.navigator import NavigationError, Navigator
from lowerbase.world.footprint import DEFAULT_POINTS, Footprint
from lowerbase.world.maps import load_map

START = (5.0, 4.0, 0.0)
NEAR_WALL = (9.32, 4.0, math.pi / 2)  # 0.48 m from the east wall's face (x = 9.8)
BIGGER = [(1.5 * x, 1.5 * y) for x, y in DEFAULT_POINTS]


def _radii(points: list[tuple[float, float]]) -> tuple[float, float]:
    """costmap_2d's inscribed (nearest edge) and circumscribed (farthest vertex) radii of the
    polygon padded by 0.1 m, computed here from the vertices."""
    padded = Footprint(tuple(points)).padded(0.1).points
    edges = []
    for (x1, y1), (x2, y2) in zip(padded, padded[1:] + padded[:1], strict=True):
        length = math.hypot(x2 - x1, y2 - y1)
        t = max(0.0, min(1.0, -(x1 * (x2 - x1) + y1 * (y2 - y1)) / length ** 2))
        edges.append(math.hypot(x1 + t * (x2 - x1), y1 + t * (y2 - y1)))
    return min(edges), max(math.hypot(x, y) for x, y in padded)


def _state(nav: Navigator) -> tuple[object, ...]:
    return (nav.global_costmap.inscribed_radius, nav.local_costmap.inscribed_radius,
            tuple(map(tuple, nav.controller.footprint.points)), nav.combined.costs.tobytes())


def test_each_costmap_takes_its_own_footprint_and_the_global_one_drives_the_checks() -> None:
    nav = Navigator(load_map("empty_room"))
    small, big = _radii(list(DEFAULT_POINTS)), _radii(BIGGER)
    assert nav.global_costmap.inscribed_radius == pytest.approx(small[0])
    checked = tuple(map(tuple, nav.controller.footprint.points))
    assert nav.make_plan(START, NEAR_WALL).ok
    nav.set_footprint(BIGGER, "local")
    assert nav.local_costmap.inscribed_radius == pytest.approx(big[0])
    assert nav.local_costmap.circumscribed_radius == pytest.approx(big[1])
    assert nav.global_costmap.inscribed_radius == pytest.approx(small[0])
    assert tuple(map(tuple, nav.controller.footprint.points)) == checked
    assert nav.make_plan(START, NEAR_WALL).ok
    nav.set_footprint(DEFAULT_POINTS, "local")
    nav.set_footprint(BIGGER, "global")
    assert nav.global_costmap.inscribed_radius == pytest.approx(big[0])
    assert nav.local_costmap.inscribed_radius == pytest.approx(small[0])
    padded = Footprint(tuple(BIGGER)).padded(0.1).points
    assert [c for p in nav.controller.footprint.points for c in p] == \
        pytest.approx([c for p in padded for c in p])
    assert not nav.make_plan(START, NEAR_WALL).ok  # the bigger robot does not fit there
    nav.set_footprint(DEFAULT_POINTS)  # "both"
    assert nav.local_costmap.inscribed_radius == nav.global_costmap.inscribed_radius \
        == pytest.approx(small[0])
    assert tuple(map(tuple, nav.controller.footprint.points)) == checked
    assert nav.make_plan(START, NEAR_WALL).ok


@pytest.mark.parametrize(("points", "which", "error"), [
    (BIGGER, "lokal", NavigationError),
    (BIGGER[:2], "global", WorldError),
    ([(math.nan, 0.0), (1.0, 1.0), (-1.0, 1.0)], "both", WorldError),
])
def test_a_bad_footprint_or_costmap_name_changes_nothing(
        points: list[tuple[float, float]], which: str, error: type[Exception]) -> None:
    nav = Navigator(load_map("empty_room"))
    before = _state(nav)
    with pytest.raises(error) as info:
        nav.set_footprint(points, which)
    assert "\n" not in str(info.value)
    assert _state(nav) == before
