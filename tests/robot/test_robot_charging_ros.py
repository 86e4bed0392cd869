"""A charging task end to end, black-box, on a real rosmaster: ``lowerbase robot --map
empty_room --sim-time --speed 1 --ground-truth --soc 30`` (world, emulate, driver, navigation,
tasks) and a user's rospy script that knows only the seed's interface
(tests/robot/charging_client.py: exec_task, robot_status, /battery). The robot drives to the
charger, docks, the emulator's charger contact closes, robot_state turns charging, /battery
shows the charge current and the charge rising; a parking task then undocks it and parks it
at ``start``. Where it stands is checked on the emulator's ground truth (``--truth``)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from lowerbase.simloop.truth import TruthFollower
from lowerbase.world.maps import load_map
from lowerbase.world.places import load_places
from tests.driver.conftest import require_ros, ros_master, woosh_msgs_build  # noqa: F401
from tests.robot.test_robot_ros import Robot
from tests.robot.test_robot_whole_ros import near, standing

CLIENT = Path(__file__).with_name("charging_client.py")
NAVIGATION, DOCK_IN, CHARGING, DOCK_OUT = 1, 3, 7, 4
EXECUTING, COMPLETED = 3, 7
CHARGING_STATE, IDLE = 8, 2


def collapsed(items: list[Any]) -> list[Any]:
    """``items`` with runs of equal neighbours kept once."""
    return [x for i, x in enumerate(items) if i == 0 or x != items[i - 1]]


@pytest.mark.ros
@pytest.mark.process
def test_a_users_charging_task_docks_charges_and_a_new_task_undocks(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    require_ros(("rospy", "actionlib", "tf2_ros", "nav_msgs.srv", "std_srvs.srv"))
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    places = load_places("empty_room", load_map("empty_room"))
    start = places.named()["start"]
    assert places.charger is not None
    truth_file = tmp_path / "truth.csv"
    robot = Robot(env, tmp_path / "logs", "--truth", str(truth_file), "--ground-truth",
                  "--soc", "30", "--sim-time", "--speed", "1")
    try:
        robot.wait_for("ready on ROS master", timeout=240.0)
        out = subprocess.run(
            [sys.executable, str(CLIENT), "--task-id", "31", "--mark", "start"],
            capture_output=True, text=True, env={**os.environ, **ros_master.env}, timeout=600)
        at = standing(TruthFollower(truth_file), start)
    finally:
        code, shown, err = robot.ctrl_c()
    logs = tmp_path / "logs"
    assert out.returncode == 0, (out.stdout[-4000:], out.stderr[-2000:],
                                 (logs / "tasks.log").read_text()[-2000:])
    assert code == 0 and "Traceback" not in err, err
    lines = out.stdout.splitlines()
    answers = [json.loads(x[10:]) for x in lines if x.startswith("exec_task ")]
    assert "accepted" in answers[0]["message"] and answers[1]["success"], answers
    seq = [json.loads(x[13:]) for x in lines if x.startswith("robot_status ")]
    charge = collapsed([(s["task_state"], s["action_type"]) for s in seq if s["task_id"] == 31])
    # executing: navigation to the approach pose, dock in, charging; ended by the new task
    assert charge[:3] == [(EXECUTING, NAVIGATION), (EXECUTING, DOCK_IN),
                          (EXECUTING, CHARGING)], charge
    assert charge[-1] == (COMPLETED, CHARGING), charge
    ended = next(s for s in seq if s["task_id"] == 31 and s["task_state"] == COMPLETED)
    assert "charging ended" in ended["msg"] and "for task 32" in ended["msg"], ended
    assert any(s["robot_state"] == CHARGING_STATE and s["action_type"] == CHARGING
               for s in seq if s["task_id"] == 31), seq
    # the new task undocks first (dock out), then drives, then completes; idle again
    park = collapsed([(s["task_state"], s["action_type"]) for s in seq if s["task_id"] == 32])
    assert park == [(EXECUTING, DOCK_OUT), (EXECUTING, NAVIGATION), (COMPLETED, NAVIGATION)], \
        park
    assert seq[-1]["robot_state"] == IDLE
    # /battery: discharging before, charging (current in, capacity rising) on the charger,
    # discharging again after the undock
    battery = {b["when"]: b for b in (json.loads(x[8:]) for x in lines
                                      if x.startswith("battery "))}
    assert battery["before"]["chargeStatus"] == 0 and battery["before"]["batteryCurrent"] < 0
    assert battery["charging"]["chargeStatus"] == 1 and battery["charging"]["batteryCurrent"] > 0
    assert battery["charged"]["capacityRemain"] >= battery["charging"]["capacityRemain"] + 0.02
    assert battery["charged"]["batteryPercentage"] >= battery["charging"]["batteryPercentage"]
    assert battery["after"]["chargeStatus"] == 0 and battery["after"]["batteryCurrent"] < 0
    # the emulator's charger contact closed on the charger and opened when it left (lockstep:
    # the robot's own output)
    emulate = "".join(robot.lines) + shown
    assert emulate.count("charger contact closed") >= 1, emulate[-2000:]
    assert "charger contact opened: the robot left the charger" in emulate
    # it truly parks at start again (move_base's 5 cm / 2 deg; the pose is the truth here)
    assert near(at, start, 0.08, math.radians(4.0)), (at, start)
    assert math.isfinite(at[0])
