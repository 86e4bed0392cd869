"""The global planner on plain cost arrays (tests/navigation/costs.py inflates them with
costmap_2d's formula, independently of lowerbase.navigation's costmap)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from lowerbase.errors import LowerbaseError
from lowerbase.navigation.planner import (
    INSCRIBED,
    LETHAL,
    GlobalPlanner,
    PlanningError,
)
from lowerbase.world.footprint import contact
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.maps import load_map
from lowerbase.world.places import load_places
from tests.navigation.costs import PADDED, inflate

Pose = tuple[float, float, float]
World = tuple[OccupancyGrid, GlobalPlanner]


@pytest.fixture(scope="module")
def warehouse() -> World:
    grid = load_map("warehouse")
    return grid, GlobalPlanner(inflate(grid), grid.resolution, grid.origin[:2],
                               footprint=PADDED.points)


def _max_deviation(poses: list[tuple[float, float, float]], a: tuple[float, float],
                   b: tuple[float, float]) -> float:
    (ax, ay), (bx, by) = a, b
    n = math.hypot(bx - ax, by - ay)
    return max(abs((bx - ax) * (ay - y) - (ax - x) * (by - ay)) / n for x, y, _ in poses)


@pytest.mark.parametrize("start, goal", [
    ((1.0, 1.0, 0.3), (8.3, 5.7, -1.0)),
    ((0.52, 7.1, 0.0), (9.4, 0.33, 2.0)),
    ((2.0, 2.0, 0.0), (2.0, 6.5, 0.5)),
])
def test_straight_line_in_free_space_is_the_closed_form(start: Pose, goal: Pose) -> None:
    planner = GlobalPlanner(np.zeros((160, 200), np.uint8), 0.05)
    plan = planner.make_plan(start, goal)
    assert plan.ok and plan.reason == ""
    assert plan.length == pytest.approx(math.hypot(goal[0] - start[0], goal[1] - start[1]),
                                        abs=1e-9)
    assert plan.poses[0][:2] == pytest.approx(start[:2])
    assert plan.poses[-1] == pytest.approx(goal)  # the goal's yaw at the end
    assert _max_deviation(plan.poses, start[:2], goal[:2]) < 1e-9
    heading = math.atan2(goal[1] - start[1], goal[0] - start[0])
    assert all(p[2] == pytest.approx(heading) for p in plan.poses[:-1])
    steps = np.hypot(*np.diff(np.asarray(plan.poses)[:, :2], axis=0).T)
    assert steps.max() <= 0.05 + 1e-9  # dense, as nav_msgs/Path from a grid planner


def test_plan_around_walls_is_collision_free_for_the_padded_footprint(warehouse: World) -> None:
    grid, planner = warehouse
    places = load_places("warehouse", grid)
    start = places.pose("start")
    for name in ("B4-02", "A5-03", "office", "B1-01"):
        goal = places.pose(name)
        plan = planner.make_plan(start, goal)
        assert plan.ok, (name, plan.reason)
        straight = math.hypot(goal[0] - start[0], goal[1] - start[1])
        assert plan.length > straight  # it goes around something
        assert plan.poses[-1] == pytest.approx(goal)
        for pose in plan.poses[1:-1]:
            assert contact(pose, grid, footprint=PADDED) is None, (name, pose)
            assert planner.cost_at(pose[0], pose[1]) < INSCRIBED


def test_random_warehouse_plans_never_touch_a_wall(warehouse: World) -> None:
    grid, planner = warehouse
    rng = np.random.default_rng(7)
    free = np.argwhere(planner.costs == 0)
    for _ in range(15):
        a, b = free[rng.integers(len(free), size=2)]
        plan = planner.make_plan((*planner.centre(*a), 0.0), (*planner.centre(*b), 0.0))
        assert plan.ok
        for pose in plan.poses[1:-1]:
            assert contact(pose, grid, footprint=PADDED) is None, pose


def _reachable(planner: GlobalPlanner, start: tuple[float, float]) -> np.ndarray:
    labels, _ = ndimage.label(~planner.blocked, structure=np.ones((3, 3)))
    return labels == labels[planner.cell(*start)]


def test_blocked_goal_plans_within_tolerance_to_the_nearest_free_cell(warehouse: World) -> None:
    grid, planner = warehouse
    start = (4.0, 4.0, 0.0)
    goal = (12.5, 6.0, 1.0)  # inside a rack row
    assert planner.costs[planner.cell(goal[0], goal[1])] == LETHAL
    refused = planner.make_plan(start, goal, tolerance=0.0)
    assert not refused.ok and "blocked" in refused.reason
    plan = planner.make_plan(start, goal, tolerance=1.5)
    assert plan.ok and plan.goal is not None
    end = plan.poses[-1]
    # independent answer: the nearest cell centre that is passable and connected to the start
    rows, cols = np.nonzero(_reachable(planner, start[:2]))
    xs = grid.origin[0] + (cols + 0.5) * grid.resolution
    ys = grid.origin[1] + (rows + 0.5) * grid.resolution
    nearest = np.hypot(xs - goal[0], ys - goal[1]).min()
    assert math.hypot(end[0] - goal[0], end[1] - goal[1]) == pytest.approx(nearest)
    assert nearest <= 1.5
    assert end[2] == goal[2]
    assert not planner.make_plan(start, goal, tolerance=0.2).ok


def test_unreachable_goal_gives_an_empty_plan_and_a_reason() -> None:
    costs = np.zeros((100, 100), np.uint8)
    costs[40:61, 40] = costs[40:61, 60] = costs[40, 40:61] = costs[60, 40:61] = LETHAL
    planner = GlobalPlanner(costs, 0.1)
    plan = planner.make_plan((1.0, 1.0, 0.0), (5.0, 5.0, 0.0), tolerance=0.5)
    assert not plan.ok and plan.poses == [] and "no path" in plan.reason
    # the enclosure's inside is free: with the tolerance reaching outside it plans
    plan = planner.make_plan((1.0, 1.0, 0.0), (5.0, 5.0, 0.0), tolerance=1.2)
    assert plan.ok and math.hypot(plan.poses[-1][0] - 5.0, plan.poses[-1][1] - 5.0) <= 1.2


def test_inscribed_and_unknown_cells_are_impassable() -> None:
    costs = np.zeros((50, 50), np.uint8)
    costs[:, 25] = INSCRIBED
    assert not GlobalPlanner(costs, 0.1).make_plan((1, 1, 0), (4, 1, 0)).ok
    costs[:, 25] = 255
    assert not GlobalPlanner(costs, 0.1).make_plan((1, 1, 0), (4, 1, 0)).ok
    assert GlobalPlanner(costs, 0.1, allow_unknown=True).make_plan((1, 1, 0), (4, 1, 0)).ok
    costs[:, 25] = 252  # costly but passable
    assert GlobalPlanner(costs, 0.1).make_plan((1, 1, 0), (4, 1, 0)).ok


def test_plan_prefers_low_cost_over_a_costly_shortcut() -> None:
    costs = np.zeros((60, 60), np.uint8)
    costs[10:50, 28:32] = 200  # a costly band across the direct line
    planner = GlobalPlanner(costs, 0.1, cost_scale=10.0)
    plan = planner.make_plan((1.0, 3.0, 0.0), (5.0, 3.0, 0.0))
    assert plan.ok
    assert max(planner.cost_at(x, y) for x, y, _ in plan.poses) == 0  # it went round


@pytest.mark.parametrize("start, why", [
    ((12.5, 6.0, 0.0), "in an obstacle"),
    ((-3.0, 1.0, 0.0), "outside"),
    ((float("nan"), 1.0, 0.0), "finite"),
])
def test_bad_start_is_a_clear_error(warehouse: World, start: Pose, why: str) -> None:
    _, planner = warehouse
    with pytest.raises(PlanningError, match=why) as info:
        planner.make_plan(start, (4.0, 4.0, 0.0))
    assert isinstance(info.value, LowerbaseError)
    assert "\n" not in str(info.value)


def test_bad_input_is_refused() -> None:
    with pytest.raises(PlanningError, match="uint8"):
        GlobalPlanner(np.zeros((5, 5)), 0.1)
    with pytest.raises(PlanningError, match="resolution"):
        GlobalPlanner(np.zeros((5, 5), np.uint8), 0.0)
    planner = GlobalPlanner(np.zeros((50, 50), np.uint8), 0.1)
    with pytest.raises(PlanningError, match="tolerance"):
        planner.make_plan((1, 1, 0), (2, 2, 0), tolerance=-1.0)
    with pytest.raises(PlanningError, match="goal"):
        planner.make_plan((1, 1, 0), (2, float("inf"), 0))


def test_plans_on_the_navigation_global_costmap() -> None:
    from lowerbase.navigation.costmap import global_costmap

    grid = load_map("warehouse")
    costmap = global_costmap(grid)
    planner = GlobalPlanner.from_costmap(costmap, footprint=PADDED.points)
    goal = (21.0, 9.75, 3.0)
    plan = planner.make_plan((4.0, 4.0, 0.0), goal)
    assert plan.ok and plan.poses[-1] == pytest.approx(goal)
    for pose in plan.poses[1:-1]:
        assert contact(pose, grid, footprint=PADDED) is None


def test_far_off_poses_are_answered_not_overflowed() -> None:
    """A goal at 1e308 m is a plan with a reason (quoted as %g), a start there a
    PlanningError: never OverflowError from the cell arithmetic."""
    planner = GlobalPlanner(np.zeros((50, 50), np.uint8), 0.1)
    plan = planner.make_plan((1.0, 1.0, 0.0), (1e308, -1e308, 0.0), tolerance=1e308)
    assert not plan.ok and "(1e+308, -1e+308)" in plan.reason
    assert not planner.make_plan((1.0, 1.0, 0.0), (6.0, 1.0, 0.0)).ok  # just off: no cell
    with pytest.raises(PlanningError, match=r"the start \(1e\+308, 1.00\) is outside"):
        planner.make_plan((1e308, 1.0, 0.0), (1.0, 1.0, 0.0))
