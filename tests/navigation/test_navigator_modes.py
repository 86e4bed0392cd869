"""/navigation_mode on the Navigator: each mode behaves differently in front of a box blocking
the path (empty_room, robot at (2, 4) heading for (8, 4), a 0.6 m crate at (5, 4)), checked on
the emulator's ground truth."""

from __future__ import annotations

import math

import pytest

from lowerbase.navigation.controller import Status
from lowerbase.navigation.modes import Mode, NavigationModeGoal
from lowerbase.navigation.navigator import GoalState, Navigator
from lowerbase.navigation.sim import NavRun, NavSim
from lowerbase.world.maps import load_map
from tests.navigation.drive import box, distance_to, nav_world

GOAL = (8.0, 4.0, 0.0)
CRATE = (5.0, 4.0)  # 0.6 m square: its centre is 0.3 m inside its faces


def _blocked_world(mode: NavigationModeGoal) -> NavSim:
    sim = nav_world("empty_room", (2.0, 4.0, 0.0))
    ok, text = sim.navigator.set_mode(mode)
    assert ok, text
    sim.set_obstacles([box("crate", *CRATE)])
    return sim


def _blocked_ticks(run: NavRun) -> list[int]:
    return [i for i, c in enumerate(run.commands) if c.status is Status.BLOCKED]


def test_fuzzy_and_precise_avoid_at_once_with_different_clearance() -> None:
    nearest = {}
    for mode in (0, 1):
        sim = _blocked_world(NavigationModeGoal(navigation_mode=mode))
        run = sim.go_to(GOAL, timeout=40.0)
        assert run.state is GoalState.SUCCEEDED, run.reason
        assert run.contacts == 0 and not _blocked_ticks(run)  # replanned before stopping
        assert sim.navigator.early_replans >= 1
        nearest[mode] = distance_to(run.path, *CRATE)
    padded = sim.navigator.global_costmap
    # fuzzy: the inscribed radius + 0.1 m from the crate's face; precise: circumscribed + 0.1
    assert 0.3 + padded.inscribed_radius + 0.05 <= nearest[0] < 0.3 + padded.circumscribed_radius
    assert nearest[1] >= 0.3 + padded.circumscribed_radius + 0.05
    assert nearest[1] > nearest[0] + 0.15


def test_stop_and_wait_waits_until_the_box_is_removed() -> None:
    sim = _blocked_world(NavigationModeGoal(navigation_mode=2))
    nav = sim.navigator
    nav.send_goal(GOAL, now=sim.now)
    sim.run(12.0)
    assert nav.state is GoalState.ACTIVE and sim.last is not None
    assert sim.last.status is Status.BLOCKED and "obstacle" in sim.last.reason
    x, y, _ = sim.world.true_pose()
    assert x < CRATE[0] - 0.3 - 0.4 and abs(y - 4.0) < 0.1  # in front of it, on the line
    before = sim.world.true_pose()
    sim.run(3.0)  # still waiting: no replan, no motion, no abort (waiting is not stuck)
    after = sim.world.true_pose()
    assert math.hypot(after[0] - before[0], after[1] - before[1]) < 1e-3
    assert nav.state is GoalState.ACTIVE and nav.replans == nav.early_replans == 0
    sim.set_obstacles([])
    ran = sim.run_until(lambda s: s.navigator.state is not GoalState.ACTIVE, 30.0)
    assert ran and nav.state is GoalState.SUCCEEDED
    assert sim.contacts == 0
    x, y, _ = sim.world.true_pose()
    assert math.hypot(x - GOAL[0], y - GOAL[1]) <= 0.05


def test_wait_then_avoid_waits_the_timeout_then_avoids_precisely() -> None:
    sim = _blocked_world(NavigationModeGoal(navigation_mode=3, waiting_timeout=3.0))
    run = sim.go_to(GOAL, timeout=40.0)
    assert run.state is GoalState.SUCCEEDED, run.reason
    blocked = _blocked_ticks(run)
    waited = (blocked[-1] - blocked[0] + 1) * 0.05
    assert 3.0 <= waited <= 3.5
    assert sim.navigator.replans == 1 and sim.navigator.early_replans == 0
    assert run.contacts == 0
    assert distance_to(run.path, *CRATE) >= 0.3 + sim.navigator.global_costmap \
        .circumscribed_radius + 0.05


def test_mode_3_with_a_negative_timeout_is_precise() -> None:
    sim = _blocked_world(NavigationModeGoal(navigation_mode=3, waiting_timeout=-1.0))
    assert sim.navigator.mode.effective_mode is Mode.PRECISE
    run = sim.go_to(GOAL, timeout=40.0)
    assert run.state is GoalState.SUCCEEDED and not _blocked_ticks(run)
    assert sim.navigator.early_replans >= 1


def test_no_permitted_passage_waits_instead_of_taking_a_changed_path() -> None:
    sim = _blocked_world(NavigationModeGoal(navigation_mode=1, permitted_passage=False))
    nav = sim.navigator
    nav.send_goal(GOAL, now=sim.now)
    sim.run(12.0)
    assert nav.state is GoalState.ACTIVE and nav.replans == nav.early_replans == 0
    assert sim.last is not None and sim.last.status is Status.BLOCKED
    assert sim.world.true_pose()[0] < CRATE[0] - 0.7 and sim.contacts == 0


@pytest.mark.parametrize("goal, words", [
    (NavigationModeGoal(navigation_mode=4), "navigation_mode 4"),
    (NavigationModeGoal(navigation_mode=-1), "navigation_mode -1"),
    (NavigationModeGoal(waiting_timeout=math.nan), "waiting_timeout"),
    (NavigationModeGoal(max_speed=math.inf), "max_speed"),
    (NavigationModeGoal(nav_dir=4), "nav_dir 4"),
    (NavigationModeGoal(id=-1), "uint32"),
    (NavigationModeGoal(capacity=2**32), "uint32"),
])
def test_invalid_modes_are_refused_and_change_nothing(goal: NavigationModeGoal,
                                                      words: str) -> None:
    nav = Navigator(load_map("empty_room"))
    before = nav.mode
    ok, text = nav.set_mode(goal)
    assert not ok and words in text and "\n" not in text
    assert nav.mode is before
    assert goal.check()


def test_mode_fields_are_stored_and_reported() -> None:
    nav = Navigator(load_map("empty_room"))
    goal = NavigationModeGoal(navigation_mode=0, id=7, capacity=3, max_speed=0.4, nav_dir=1)
    assert nav.set_mode(goal) == (True, "navigation mode fuzzy")
    assert nav.mode == goal and nav.controller.config.max_speed == pytest.approx(0.4)
    ok, text = nav.set_mode(NavigationModeGoal(navigation_mode=3, waiting_timeout=-2.0))
    assert ok and "precise" in text
    assert nav.set_mode(NavigationModeGoal(max_speed=9.0))[0]
    assert nav.controller.config.max_speed == pytest.approx(nav.limits.max_linear)
