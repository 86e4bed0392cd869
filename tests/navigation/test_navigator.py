"""The Navigator (move_base's core) on a WorldSim through the whole chain: goals, replanning
around a dropped box, abort, preempt, cancel, e-stop, speed cap and driving direction. Positions
are checked on the emulator's ground truth (sim.true_pose)."""

from __future__ import annotations

import math

import pytest

from lowerbase.driver.services import send_control
from lowerbase.errors import LowerbaseError
from lowerbase.navigation.controller import Status, wrap
from lowerbase.navigation.modes import NavigationModeGoal
from lowerbase.navigation.navigator import (
    GoalState,
    NavigationError,
    Navigator,
    NavigatorConfig,
)
from lowerbase.navigation.sim import NavRun, NavSim
from lowerbase.world.maps import load_map
from tests.navigation.drive import box, distance_to, nav_world


def _error(sim: NavSim, goal: tuple[float, float, float]) -> tuple[float, float]:
    x, y, yaw = sim.world.true_pose()
    return math.hypot(x - goal[0], y - goal[1]), abs(wrap(yaw - goal[2]))


def test_reaches_a_goal_across_the_warehouse_racks_with_amcl() -> None:
    sim = nav_world("warehouse", "start", localization="filter")
    goal = (9.5, 9.75, 0.0)  # storage A3-01, behind the first rack row
    run = sim.go_to(goal, timeout=60.0)
    assert run.state is GoalState.SUCCEEDED, run.reason
    assert run.contacts == 0
    est = sim.pose()
    assert math.hypot(est[0] - goal[0], est[1] - goal[1]) <= 0.05
    assert abs(wrap(est[2] - goal[2])) <= math.radians(2.0)
    d, a = _error(sim, goal)  # truth = estimate + amcl's error (a few cm)
    assert d <= 0.10 and a <= math.radians(3.0)
    straight = math.hypot(goal[0] - 4.0, goal[1] - 4.0)
    assert run.length > straight + 0.5  # it went round the rack, not through it
    assert sim.navigator.distance_remaining < 0.06


def test_a_box_dropped_on_the_path_is_avoided_without_contact() -> None:
    sim = nav_world("empty_room", (2.0, 4.0, 0.0))

    def drop(s: NavSim, run: NavRun) -> None:
        if run.path and run.path[-1][0] > 2.5 and not len(s.world.obstacles):
            s.set_obstacles([box("crate", 5.0, 4.0)])

    run = sim.go_to((8.0, 4.0, 0.0), timeout=40.0, during=drop)
    assert run.state is GoalState.SUCCEEDED, run.reason
    assert len(sim.world.obstacles) == 1 and run.contacts == 0
    assert sim.navigator.early_replans + sim.navigator.replans >= 1
    assert max(abs(p[1] - 4.0) for p in run.path) > 0.7  # went round it
    d, a = _error(sim, (8.0, 4.0, 0.0))
    assert d <= 0.05 and a <= math.radians(2.0)


def test_a_goal_in_a_wall_is_aborted_with_a_reason() -> None:
    sim = nav_world("empty_room", (2.0, 4.0, 0.0))
    run = sim.go_to((0.0, 4.0, 0.0), timeout=5.0)
    assert run.state is GoalState.ABORTED
    assert run.reason.startswith("no path")
    assert run.duration <= 0.1  # decided at the first tick, the robot never moved


def test_endless_detours_are_bounded_by_max_early_replans() -> None:
    ring = [box(f"b{i}", 6.0 + 1.2 * math.cos(a), 4.0 + 1.2 * math.sin(a), 0.7)
            for i, a in enumerate(k * math.pi / 4 for k in range(8))]  # gaps too narrow
    sim = nav_world("empty_room", (2.0, 4.0, 0.0), config=NavigatorConfig(max_early_replans=3))
    sim.set_obstacles(ring)
    run = sim.go_to((6.0, 4.0, 0.0), timeout=60.0)
    assert run.state is GoalState.ABORTED
    assert run.reason.startswith("no way found: replanned 3 times"), run.reason
    assert sim.navigator.early_replans == 4 and run.contacts == 0


def test_a_new_goal_preempts_the_active_one() -> None:
    sim = nav_world("empty_room", (2.0, 4.0, 0.0))
    nav = sim.navigator
    nav.send_goal((8.0, 4.0, 0.0), now=sim.now)
    sim.run(2.0)
    assert nav.state is GoalState.ACTIVE
    run = sim.go_to((2.0, 6.0, math.pi / 2), timeout=40.0)
    assert [r.state for r in nav.results] == [GoalState.PREEMPTED, GoalState.SUCCEEDED]
    assert nav.results[0].reason == "preempted by a new goal"
    assert run.state is GoalState.SUCCEEDED
    d, a = _error(sim, (2.0, 6.0, math.pi / 2))
    assert d <= 0.05 and a <= math.radians(2.0)


def test_cancel_stops_the_robot() -> None:
    sim = nav_world("empty_room", (2.0, 4.0, 0.0))
    nav = sim.navigator
    nav.send_goal((8.0, 4.0, 0.0), now=sim.now)
    sim.run(3.0)
    nav.cancel(sim.now)
    assert nav.state is GoalState.PREEMPTED and nav.results[-1].reason == "cancelled"
    sim.run(2.0)  # braking
    before = sim.world.true_pose()
    sim.run(1.0)
    after = sim.world.true_pose()
    assert before[0] > 2.3  # it had been moving
    assert math.hypot(after[0] - before[0], after[1] - before[1]) < 1e-3
    assert sim.tick().linear == 0.0 and sim.last is not None
    assert sim.last.state is GoalState.PREEMPTED


def test_an_estop_through_the_driver_stops_the_chassis_and_the_goal_aborts_stuck() -> None:
    sim = nav_world("empty_room", (2.0, 4.0, 0.0), config=NavigatorConfig(stuck_timeout=3.0))

    def press(s: NavSim, run: NavRun) -> None:
        if s.now >= 4.0 and not s.world.loop.driver.e_stopped:
            ok, _ = send_control(s.world.loop.driver, "EStopSet")
            assert ok

    run = sim.go_to((8.0, 4.0, 0.0), timeout=30.0, during=press)
    assert run.state is GoalState.ABORTED
    assert run.reason.startswith("stuck")
    assert 3.0 <= run.duration - 3.0 <= 6.0  # pressed at t = 4 s (the goal started at 1 s)
    tail = run.path[-40:]  # the last 2 s: standing still while commanded to go
    assert math.hypot(tail[-1][0] - tail[0][0], tail[-1][1] - tail[0][1]) < 1e-3
    assert any(abs(c.linear) > 0.1 for c in run.commands[-40:])
    assert run.path[-1][0] < 8.0 - 0.5


@pytest.mark.parametrize("max_speed, cap", [(0.3, 0.3), (0.0, 0.6)])
def test_max_speed_caps_the_driven_speed(max_speed: float, cap: float) -> None:
    sim = nav_world("empty_room", (1.5, 4.0, 0.0))
    ok, _ = sim.navigator.set_mode(NavigationModeGoal(max_speed=max_speed))
    assert ok
    run = sim.go_to((8.5, 4.0, 0.0), timeout=40.0)
    assert run.state is GoalState.SUCCEEDED
    assert run.max_commanded <= cap + 1e-9
    assert cap - 0.05 <= run.max_driven <= cap + 0.03  # the chassis reached the cap, not more


def test_nav_dir_backward_drives_the_path_in_reverse() -> None:
    sim = nav_world("empty_room", (2.0, 4.0, 0.0))
    ok, _ = sim.navigator.set_mode(NavigationModeGoal(nav_dir=2))
    assert ok
    run = sim.go_to((5.0, 4.5, 0.0), timeout=40.0)
    assert run.state is GoalState.SUCCEEDED, run.reason
    moving = [c.linear for c in run.commands if abs(c.linear) > 0.05]
    assert moving and all(v < 0 for v in moving)
    d, a = _error(sim, (5.0, 4.5, 0.0))
    assert d <= 0.05 and a <= math.radians(2.0)


@pytest.mark.parametrize("mode", [1, 0])
def test_poses_are_followed_point_by_point_or_freely(mode: int) -> None:
    sim = nav_world("empty_room", (2.0, 2.0, 0.0))
    via = (5.0, 2.0, math.pi / 2)
    run = sim.go_to((5.0, 5.0, math.pi / 2), poses=[via], execution_mode=mode, timeout=60.0)
    assert run.state is GoalState.SUCCEEDED, run.reason
    assert distance_to(run.path, via[0], via[1]) <= (0.05 if mode == 1 else 0.5)
    near = [i for i, p in enumerate(run.path) if math.hypot(p[0] - via[0], p[1] - via[1]) < 0.1]
    stopped = [c for c in run.commands if c.reason == "waypoint reached"]
    assert len(stopped) == (1 if mode == 1 else 0)
    if mode == 1:  # it stood at the pose, facing its yaw, before going on
        i = run.commands.index(stopped[0])
        assert abs(wrap(run.path[i][2] - via[2])) <= math.radians(2.0)
    else:
        assert not near or run.max_driven > 0.3


def test_bad_goals_are_refused_with_one_line_and_change_nothing() -> None:
    nav = Navigator(load_map("empty_room"))
    with pytest.raises(NavigationError, match="finite"):
        nav.send_goal((math.nan, 1.0, 0.0))
    with pytest.raises(NavigationError, match="off the map"):
        nav.send_goal((500.0, 1.0, 0.0))
    with pytest.raises(NavigationError, match="execution_mode"):
        nav.send_goal((3.0, 3.0, 0.0), execution_mode=7)
    assert nav.state is None and nav.goal_id == 0
    assert issubclass(NavigationError, LowerbaseError)
    cmd = nav.tick(0.0, (3.0, 3.0, 0.0))
    assert (cmd.linear, cmd.angular, cmd.status) == (0.0, 0.0, Status.IDLE)
    with pytest.raises(NavigationError, match="stuck_timeout"):
        NavigatorConfig(stuck_timeout=math.nan)


def test_off_map_poses_are_refused_compactly_without_a_traceback() -> None:
    """/move_base/make_plan with a goal (or start) at 1e308 is refused with a LowerbaseError
    (the service answers an empty plan and logs one line), not an OverflowError from the
    cell arithmetic; a refusal quotes such numbers as %g, not as 300 digits."""
    nav = Navigator(load_map("empty_room"))  # 10 x 8.6 m
    for start, goal in (((1.0, 1.0, 0.0), (1e308, 0.0, 0.0)),
                        ((1.0, 1.0, 0.0), (-1e308, 1e308, 0.0)),
                        ((1e308, 1.0, 0.0), (3.0, 3.0, 0.0)),
                        ((1.0, 1.0, 0.0), (50.0, 3.0, 0.0))):
        with pytest.raises(LowerbaseError, match="off the map") as info:
            nav.make_plan(start, goal)
        assert "\n" not in str(info.value) and len(str(info.value)) < 160
    with pytest.raises(LowerbaseError, match=r"\(1e\+308, 0.00\)"):
        nav.make_plan((1.0, 1.0, 0.0), (1e308, 0.0, 0.0))
    # a goal just off the map within the tolerance still plans to the nearest free cell
    assert nav.make_plan((1.0, 1.0, 0.0), (10.1, 4.0, 0.0), tolerance=1.0).ok
    with pytest.raises(NavigationError) as refused:
        nav.send_goal((1e300, 2.0, 0.0))
    assert str(refused.value) == ("the goal (1e+300, 2.00) is off the map (x 0.00..10.00 m, "
                                  "y 0.00..8.60 m): give a pose on the map")
