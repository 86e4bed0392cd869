"""The whole robot, black-box: ``lowerbase robot --map warehouse`` (world with amcl
localization, emulate, driver, navigation, tasks: five processes, real time) on a master of the
test's own. A move_base goal through actionlib's SimpleActionClient succeeds, and a user's
transport task (examples/transport_task.py: exec_task and robot_status) completes; where the
robot ends up is checked on the emulator's ground truth (``lowerbase robot --truth FILE``)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from lowerbase.simloop.truth import TruthFollower
from lowerbase.world.localization.poses import compose
from lowerbase.world.maps import load_map
from lowerbase.world.places import load_places
from tests.conftest import ROOT
from tests.driver.conftest import require_ros, ros_master, woosh_msgs_build  # noqa: F401
from tests.navigation.ros_client import NavClient
from tests.robot.test_robot_ros import Robot

MOVE = "woosh_msgs/MoveBaseAction"
SUCCEEDED = 3
Pose = tuple[float, float, float]


def true_map_pose(truth: TruthFollower, start: Pose) -> Pose:
    """The emulator's newest true pose, on the map (its frame starts at the map's start)."""
    row = truth.latest()
    assert row is not None, f"no ground truth in {truth.path}"
    return compose(start, (row[1], row[2], row[3]))


def standing(truth: TruthFollower, start: Pose, timeout: float = 60.0) -> Pose:
    """The true map pose once the robot has stopped (two rows of the emulator's truth 0.1 s or
    more apart agree within 1 mm)."""
    first = None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        row = truth.latest()
        if row is not None and (first is None or math.hypot(row[1] - first[1],
                                                               row[2] - first[2]) >= 0.001):
            first = row
        elif row is not None and row[0] >= first[0] + 0.1:
            return compose(start, (row[1], row[2], row[3]))
        time.sleep(0.02)  # the truth's rows come every 20 ms
    raise AssertionError(f"the robot did not stand still within {timeout} s: {first}")


def near(pose: Pose, target: Pose, xy: float, yaw: float) -> bool:
    return math.hypot(pose[0] - target[0], pose[1] - target[1]) < xy and \
        abs(math.remainder(pose[2] - target[2], math.tau)) < yaw


def clock_of(client: NavClient) -> float:
    msg = client.ask(op="last", topic="/clock")["msg"]
    return float(msg["clock"]) if msg is not None else 0.0


def cmd_vel_per_sim_second(client: NavClient, window: float = 3.0) -> float:
    """/base_cmd_vel messages per second of /clock over ``window`` s of it (a goal running)."""
    client.wait_last("/base_cmd_vel", lambda m: True, 60.0, "/base_cmd_vel")
    c0, n0 = clock_of(client), client.ask(op="last", topic="/base_cmd_vel")["count"]
    client.wait_last("/clock", lambda m: float(m["clock"]) > c0 + window, 60.0,
                     f"{window} s of /clock")
    c1, n1 = clock_of(client), client.ask(op="last", topic="/base_cmd_vel")["count"]
    return (n1 - n0) / (c1 - c0)


@pytest.mark.ros
@pytest.mark.process
@pytest.mark.parametrize("sim", [False, True], ids=["real-time", "lockstep-x4"])
def test_the_whole_robot_reaches_a_move_base_goal_and_completes_a_transport_task(
        ros_master: Any, tmp_path: Path, sim: bool) -> None:  # noqa: F811
    require_ros(("rospy", "actionlib", "tf2_ros", "nav_msgs.srv", "std_srvs.srv"))
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    places = load_places("warehouse", load_map("warehouse")).named()
    start = places["start"]
    truth_file = tmp_path / "truth.csv"
    extra = ("--sim-time", "--speed", "4") if sim else ()
    robot = Robot(env, tmp_path / "logs", "--map", "warehouse", "--truth", str(truth_file),
                  *extra)
    client = None
    try:
        robot.wait_for("ready on ROS master", timeout=240.0)
        assert len(robot.children()) == (0 if sim else 5)  # lockstep: one process
        client = NavClient(tmp_path, ros_master.env)
        client.ask(op="sub", topic="/robot_status", type="woosh_msgs/RobotStatus")
        for topic, kind in (("/clock", "rosgraph_msgs/Clock"),
                            ("/base_cmd_vel", "geometry_msgs/Twist")):
            client.ask(op="sub", topic=topic, type=kind)
        client.wait_last("/robot_status", lambda m: m["robot_state"] == 2, 120.0,
                         "robot_state idle")
        truth = TruthFollower(truth_file)
        assert near(standing(truth, start), start, 0.01, 0.01)
        # (a) move_base, 5.5 m east along the racks' first aisle
        goal = places["A1-01"]
        qz, qw = math.sin(goal[2] / 2), math.cos(goal[2] / 2)
        client.ask(op="send", name="/move_base", type=MOVE, goal={"target_pose": {
            "header": {"frame_id": "map"},
            "pose": {"position": {"x": goal[0], "y": goal[1]},
                     "orientation": {"z": qz, "w": qw}}}, "execution_mode": 0})
        if sim:  # the control loop's 20 Hz is per simulated second (2 per wall second here)
            rate = cmd_vel_per_sim_second(client)
            assert 0.9 * 20 <= rate <= 1.1 * 20, rate  # 10 when it paced on wall time
        for _ in range(5):  # the client waits 60 s per request
            res = client.ask(op="result", name="/move_base", timeout=120.0)
            if res["done"]:
                break
        assert res["state"] == SUCCEEDED, (res, "" if sim else (
            tmp_path / "logs" / "navigation.log").read_text()[-3000:])
        at = standing(truth, start)
        # within move_base's 5 cm / 2 deg on amcl's estimate, plus amcl's own error
        assert near(at, goal, 0.12, math.radians(5.0)), (at, goal)
        # (b) a transport task to the next aisle, as a user's script sends it
        mark = "A2-01"
        out = subprocess.run(
            [sys.executable, str(ROOT / "examples" / "transport_task.py"), "--mark", mark,
             "--task-id", "3", "--direction", "2", "--timeout", "300"],
            capture_output=True, text=True, env={**os.environ, **ros_master.env}, timeout=360)
        assert out.returncode == 0, (out.stdout[-3000:], out.stderr[-2000:], "" if sim else (
            tmp_path / "logs" / "navigation.log").read_text()[-3000:])
        at = standing(truth, start)
        assert near(at, places[mark], 0.15, 0.15), (at, places[mark])
    finally:
        if client is not None:
            client.close()
        code, out, err = robot.ctrl_c()
    assert code == 0, err
    assert "Traceback" not in err
    if not sim:
        nav_log = (tmp_path / "logs" / "navigation.log").read_text()
        assert "Traceback" not in nav_log
