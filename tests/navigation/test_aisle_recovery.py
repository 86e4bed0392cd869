"""Issue 22 item 12 (field trial): stuck in a 1.5 m aisle after one aborted goal.

With the localization's heading 6.4 deg off, a goal along a 1.5 m aisle ends ABORTED with the
robot skewed in the aisle, a rear corner a few cm from a rack, and local costmap marks 10-30 cm
into the aisle. With the heading estimate right again, every later goal used to fail in 7-10 s
without moving: the back-off went only the way the robot came (into the rack), checked with the
padded footprint; the conservative reset kept the marks beside the robot; the turn in place had
no room. The robot is free (a StepControl move forwards frees it): the recoveries must free it
too. All on the simulated clock, through driver_base's set_twist and the emulator."""

from __future__ import annotations

import math

import numpy as np

from lowerbase.navigation.navigator import GoalState, Navigator
from lowerbase.navigation.sim import NavSim
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.sim import WorldConfig, WorldSim

RES = 0.05
HEADING_ERROR = math.radians(6.4)
AISLE = (2.25, 3.75)  #: the aisle between the racks, y [m]; x from 3 to 12 m


def aisle_grid() -> OccupancyGrid:
    """15 x 6 m, walls round it, two racks 9 m long with a 1.5 m aisle between them."""
    data = np.zeros((120, 300), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[30:45, 60:240] = 100  # rack, y 1.5 .. 2.25
    data[75:90, 60:240] = 100  # rack, y 3.75 .. 4.5
    return OccupancyGrid(data, RES, (0.0, 0.0, 0.0))


class HeadingError(NavSim):
    """The localization estimate with its heading ``error`` [rad] off (the position right):
    the navigator closes the loop on it and marks the scans at it."""

    error = 0.0

    def pose(self) -> tuple[float, float, float]:
        x, y, yaw = super().pose()
        return x, y, yaw + self.error


def marks_into_aisle(sim: NavSim, low: float, high: float) -> int:
    """Local costmap marks ``low``..``high`` m into the aisle from either rack."""
    layer = sim.navigator.local_costmap.obstacle_layer
    assert layer is not None
    m = layer.map
    rows, cols = np.nonzero(m.data == 254)
    x, y = m.map_to_world(cols, rows)
    into = np.minimum(y - AISLE[0], AISLE[1] - y)
    return int(((x > 3.0) & (x < 12.0) & (into >= low) & (into <= high)).sum())


def test_later_goals_free_the_robot_after_a_goal_aborted_with_the_heading_off() -> None:
    world = WorldSim(WorldConfig(map=aisle_grid(), start=(4.5, 3.0, 0.0),
                                 localization="truth"))
    world.run(1.0)
    sim = HeadingError(world, Navigator(world.grid))
    sim.error = HEADING_ERROR
    for goal in ((10.0, 3.0, 0.0), (10.0, 3.0, 0.0), (5.0, 3.0, math.pi)):
        assert sim.go_to(goal, timeout=90.0).state is GoalState.SUCCEEDED
    aborted = sim.go_to((10.0, 3.0, 0.0), timeout=90.0)
    assert aborted.state is GoalState.ABORTED, aborted.reason  # the trial's aborted goal
    assert marks_into_aisle(sim, 0.10, 0.30) > 0  # made while the heading was off
    _, y, yaw = world.true_pose()
    assert AISLE[0] < y < AISLE[1] and abs(yaw) > math.radians(8)  # skewed in the aisle

    sim.error = 0.0  # the heading estimate right again; the marks stay
    for goal in ((10.0, 3.0, 0.0), (5.0, 3.0, math.pi), (10.0, 3.0, 0.0)):
        before = world.true_pose()
        run = sim.go_to(goal, timeout=90.0)
        after = world.true_pose()
        moved = math.hypot(after[0] - before[0], after[1] - before[1])
        assert run.state is GoalState.SUCCEEDED, \
            f"{goal}: {run.state.name} after {run.duration:.1f} s, moved {moved:.2f} m: " \
            f"{run.reason} (recoveries {sim.navigator._recovery.log})"
        assert run.contacts == 0
        assert math.hypot(after[0] - goal[0], after[1] - goal[1]) <= 0.1
