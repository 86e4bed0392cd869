"""A wrong /initialpose is said, not kept silently (issue 22 item 14): the field trial's 0.47 m
/ 14 deg off with a tight covariance reads lost from the first scan (the scan fits the map at
~20 %), LostWatch gives one line when it turns lost and one when it is localized again, and the
tasks node shows the line on robot_status."""

from __future__ import annotations

import math

from lowerbase.clock import SimClock
from lowerbase.tasks.inputs import ChassisInputs
from lowerbase.world.localization.localizer import Localizer
from lowerbase.world.localization.lostwatch import LOCALIZED, LostWatch
from tests.tasks.bench import Bench
from tests.world.localization_sim import feature_room
from tests.world.test_localization import LOOP, TIGHT, drifting_odometry, drive, path_poses


def test_a_wrong_initial_pose_is_said_once_and_so_is_the_recovery() -> None:
    grid = feature_room()
    truth = path_poses(LOOP)[:90]
    odom = drifting_odometry(path_poses(LOOP))[:90]
    x, y, yaw = truth[0]
    wrong = (x + 0.33, y + 0.33, yaw + math.radians(14.0))  # 0.47 m, 14 deg
    clock = SimClock()
    loc = Localizer(grid, clock=clock, seed=8, initial_pose=wrong, initial_cov=TIGHT)
    watch = LostWatch()
    lines = [line for _, est, _ in drive(loc, grid, truth, odom, clock)
             if (line := watch.update(est)) is not None]
    assert lines[0].startswith("lost: the scan fits the map at")
    assert "/initialpose" in lines[0] and "/global_localization" in lines[0]
    assert lines[-1] == LOCALIZED  # amcl found the pose while driving, and said so
    assert len(lines) <= 4  # on changes only, not per scan


def test_robot_status_shows_the_line_while_lost() -> None:
    inputs = ChassisInputs(link_state="ready", localization="lost: the scan fits the map "
                           "at 20 %, sigma 0.05 m / 2.0 deg (...)")
    assert inputs.chassis(0.0).uncertain.startswith("lost: the scan fits")
    inputs.localization = LOCALIZED
    assert inputs.chassis(0.0).uncertain == ""
    b = Bench()
    b.set(uncertain="lost: the scan fits the map at 20 %")
    b.tick()
    assert b.status.msg == "localization lost: the scan fits the map at 20 %"
    b.set(uncertain="", low_battery=True, soc=18.0)
    b.tick()
    assert "localization" not in b.status.msg
