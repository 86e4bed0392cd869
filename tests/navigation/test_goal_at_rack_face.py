"""A goal right at a rack face (issue: robot_status flipping WARNING / task every 50 ms at
storage mark A5-03 in benchmarks/bench_shift.py). The goal is free for the footprint but the
rack lies within the collision check's margin beyond it; the final approach used to project
the check past the goal into the rack, so it was BLOCKED when creeping and free when stopped,
every other control period. Pure kinematics on a synthetic cost array: deterministic."""

from __future__ import annotations

import math

import numpy as np

from lowerbase.navigation.controller import PathController, Status
from lowerbase.navigation.planner import LETHAL
from tests.navigation.costs import PADDED

RES = 0.05
WALL_X = 3.0  #: [m] the rack face: LETHAL from here on


def _rack_face() -> tuple[np.ndarray, PathController, float]:
    costs = np.zeros((80, 80), dtype=np.uint8)
    costs[:, round(WALL_X / RES):] = LETHAL
    ctl = PathController(costs, RES, footprint=PADDED.points)
    # the farthest x (heading +x, y = 2) whose footprint stays off the rack, less 5 cm
    xs = np.arange(1.0, WALL_X, 0.01)
    cost = ctl.footprint.max_cost(costs, (0.0, 0.0), xs, np.full_like(xs, 2.0),
                                  np.zeros_like(xs))
    free = float(xs[np.nonzero(cost < LETHAL)[0][-1]])
    return costs, ctl, free - 0.05


def _drive(ctl: PathController, pose: tuple[float, float, float], seconds: float
           ) -> list[Status]:
    x, y, yaw = pose
    statuses = []
    for _ in range(round(seconds / 0.05)):
        cmd = ctl.compute((x, y, yaw))
        statuses.append(cmd.status)
        if cmd.status is Status.SUCCEEDED:
            break
        yaw += cmd.angular * 0.05
        x += cmd.linear * 0.05 * math.cos(yaw)
        y += cmd.linear * 0.05 * math.sin(yaw)
    return statuses


def test_the_final_approach_to_a_goal_at_a_rack_face_is_not_blocked() -> None:
    _, ctl, gx = _rack_face()
    goal = (gx, 2.0, 0.0)
    start = (gx - 0.25, 2.0, 0.0)  # within approach_distance, facing the rack
    ctl.set_plan([(start[0] + 0.01 * i, 2.0, 0.0) for i in range(25)] + [goal])
    statuses = _drive(ctl, start, 20.0)
    assert Status.BLOCKED not in statuses, \
        f"{statuses.count(Status.BLOCKED)} BLOCKED periods of {len(statuses)}"
    assert statuses[-1] is Status.SUCCEEDED


def test_an_obstacle_between_the_robot_and_the_goal_still_blocks() -> None:
    costs, ctl, gx = _rack_face()
    costs[:, round((gx - 0.1) / RES):] = LETHAL  # the rack now reaches over the goal
    ctl.set_costmap(costs, RES, (0.0, 0.0))
    start = (gx - 0.25, 2.0, 0.0)
    ctl.set_plan([(start[0] + 0.01 * i, 2.0, 0.0) for i in range(25)] + [(gx, 2.0, 0.0)])
    statuses = _drive(ctl, start, 5.0)
    assert statuses[-1] is Status.BLOCKED
