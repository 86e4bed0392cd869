"""The final approach of a goal (issue 12: random warehouse goals), on the simulated clock
through the whole chain (NavSim on a WorldSim, ground-truth localization)."""

from __future__ import annotations

import math

from lowerbase.navigation.controller import wrap
from lowerbase.navigation.navigator import GoalState
from tests.navigation.drive import nav_world


def test_a_goal_beside_the_robot_within_the_tolerance_is_reached_not_stuck() -> None:
    # The goal lies 3.5 cm to the robot's left: inside xy_tolerance (5 cm) but outside the
    # half tolerance the approach drives to before turning to the goal's yaw. Driving
    # straight never brings it closer than 3.5 cm; the approach used to creep back and forth
    # at min_speed until "stuck" (benchmark goal 12 of 100 on the warehouse).
    sim = nav_world("empty_room", (5.0, 4.0, 0.0))
    start = sim.pose()
    goal = (start[0], start[1] + 0.035, 0.8)
    run = sim.go_to(goal, timeout=60.0)
    assert run.state is GoalState.SUCCEEDED, run.reason
    x, y, yaw = sim.pose()
    assert math.hypot(x - goal[0], y - goal[1]) <= 0.025
    assert abs(wrap(yaw - goal[2])) <= math.radians(1.0)
    assert run.contacts == 0
