"""/move_base/make_plan with a goal inside a rack and a huge tolerance (issue 22 item 10): the
search covers the map once instead of handing skimage every cell as an end (4.6 s before on
the warehouse, about 0.1 s now: not a timed assertion, the equivalence is what is tested), and
the ROS service plans on a copy of the costs outside the node's lock (plan_job), so the
control loop goes on meanwhile."""

from __future__ import annotations

import pytest

import lowerbase.navigation.planner as planner_mod
from lowerbase.navigation.navigator import Navigator
from lowerbase.world.maps import load_map

START = (1.0, 1.0, 0.0)
IN_A_RACK = (9.5, 8.0, 0.0)


@pytest.mark.parametrize("tolerance", [1.0, 2.0, 5.0, 1e6])
def test_the_whole_map_search_picks_what_the_per_end_search_picks(
        tolerance: float, monkeypatch: pytest.MonkeyPatch) -> None:
    nav = Navigator(load_map("warehouse"))
    fast = nav.make_plan(START, IN_A_RACK, tolerance)
    if tolerance < 10:  # the per-end search on a huge tolerance is the slow case itself
        monkeypatch.setattr(planner_mod, "FEW_ENDS", 10**9)
        slow = nav.make_plan(START, IN_A_RACK, tolerance)
        assert fast.ok == slow.ok and fast.goal == slow.goal and fast.poses == slow.poses
    assert fast.ok
    gx, gy, _ = fast.goal
    assert ((gx - IN_A_RACK[0]) ** 2 + (gy - IN_A_RACK[1]) ** 2) ** 0.5 <= tolerance


def test_a_plan_job_plans_on_the_costs_it_was_given() -> None:
    nav = Navigator(load_map("warehouse"))
    before = nav.make_plan(START, (5.0, 1.0, 0.0))
    job = nav.plan_job(START, (5.0, 1.0, 0.0))
    # the control loop runs on meanwhile and the costs change: a wall across the way
    nav.send_goal((4.0, 4.0, 0.0))
    nav.tick(0.0, START)
    nav.combined.costs[:, 55:60] = 254
    plan = job()
    assert plan.ok and plan.poses == before.poses
    assert not nav.make_plan(START, (5.0, 1.0, 0.0)).ok  # a new request sees the wall
