"""``lowerbase robot --ros2 --sim-time`` (the lockstep robot on ROS 2) with rclpy clients in
processes of their own (tests/ros2/ros2_robot_probe.py).

One robot on the smallest packaged map (empty_room, camera off) serves the module, at
``--speed max``: everything it does is on its simulated clock, so a busy host only slows it
down. The tests run in file order: the ones that look at the robot standing at its start
come before the ones that drive it.
"""

from __future__ import annotations

import json
import math
import subprocess
from collections.abc import Iterator

import pytest

from tests.conftest import ROOT
from tests.ros2.conftest import Ros2, ros2_or_skip
from tests.ros2.test_driver import robot_on_ros2

START = (5.0, 4.0, 0.0)  #: empty_room's "start" pose (lowerbase/world/maps/empty_room.*)
GOAL = (7.0, 5.0, 0.0)
XY_TOLERANCE = 0.05  #: the navigator's goal tolerance [m]
BACK = (4.0, 3.0, 0.0)  #: where /move_base drives it after GOAL
R1 = (8.0, 2.0, 0.0)  #: empty_room's storage place R1
#: move_base's ~recovery_behaviors as a ROS 2 parameter of /lowerbase_robot (ROS 1: rosparam)
RECOVERY = "_move_base/recovery_behaviors:=[rotate,clear_aggressive]"


@pytest.fixture(scope="module")
def robot() -> Iterator[Ros2]:
    ros2 = ros2_or_skip()
    with robot_on_ros2(ros2, ["--sim-time", "--map", "empty_room", "--speed", "max", RECOVERY],
                       "empty_room"):
        yield ros2


def test_odom_scan_and_clock(robot: Ros2) -> None:
    got = robot.run_json("ros2_robot_probe.py", "topics", timeout=300)
    assert got["odom_frame"] == "odom" and got["odom_child"] == "base_link"
    assert got["odom_rate"] == pytest.approx(50.0, rel=0.05)  # per second of /clock's time
    assert got["scan_frame"] == "base_link" and got["scan_beams"] == 720
    assert got["clock_last"] > got["clock_first"] and got["clock_backwards"] == 0


def test_recovery_behaviors_are_a_ros2_parameter(robot: Ros2) -> None:
    got = robot.run_json("ros2_robot_probe.py", "param", "move_base.recovery_behaviors",
                         timeout=300)
    assert got == {"type": 9, "strings": ["rotate", "clear_aggressive"]}  # STRING_ARRAY


def test_the_depth_camera_with_ros2_names(robot: Ros2) -> None:
    """``--camera`` (a robot of its own, in a domain of its own): the depth camera's info with
    ROS 2's d, k, p (ROS 1's D, K, P) and its 16-bit image."""
    own = ros2_or_skip()
    with robot_on_ros2(own, ["--sim-time", "--map", "empty_room", "--speed", "max",
                             "--camera"]):
        got = own.run_json("ros2_robot_probe.py", "camera", timeout=300)
    fx, cx, fy, cy = 385.0, 319.5, 385.0, 239.5  # CameraConfig's defaults
    assert got["info"] == [640, 480, "plumb_bob", [0.0] * 5,
                           [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                           [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]]
    assert got["image"] == [640, 480, "16UC1", 640 * 480 * 2]
    assert got["frame"] == "camera_1_depth_optical_frame"


def test_a_bad_recovery_behavior_is_one_line(robot: Ros2) -> None:
    own = ros2_or_skip()  # a domain of its own, beside the module's robot
    done = subprocess.run([str(own.python), "-m", "lowerbase", "robot", "--ros2",
                           "--sim-time", "--map", "empty_room",
                           "_move_base/recovery_behaviors:=[rotate,no_such_behavior]"],
                          env=own.env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode != 0
    assert "Traceback" not in done.stderr, done.stderr
    assert "no_such_behavior" in done.stderr.strip().splitlines()[-1], done.stderr


def test_navigation_mode(robot: Ros2) -> None:
    """The vendor's /navigation_mode on ROS 2: a known mode SUCCEEDED with result 1, an unknown
    one ABORTED with result 0 (as actionlib's set_aborted on ROS 1)."""
    got = robot.run_json("ros2_robot_probe.py", "navigation_mode", timeout=300)
    assert got == {"good": [4, 1], "bad": [6, 0]}, got  # SUCCEEDED, ABORTED


def test_late_subscriber_gets_map_and_tf_static(robot: Ros2) -> None:
    got = robot.run_json("ros2_robot_probe.py", "latched", timeout=300)
    assert (got["map_frame"], got["width"], got["height"], got["resolution"]) == \
        ("map", 200, 172, 0.05)  # empty_room.pgm: 200 x 172 cells of 5 cm
    assert got["cells"] == 200 * 172
    assert got["static"] == ["base_link->laser_back", "base_link->laser_front"]


def test_tf_map_odom_base_link_laser(robot: Ros2) -> None:
    got = robot.run_json("ros2_robot_probe.py", "tf", timeout=300)
    assert {"map->odom", "odom->base_link", "base_link->laser_front",
            "base_link->laser_back"} <= set(got["edges"])
    x, y, th = got["map_pose"]  # standing at the start, localized there
    assert math.hypot(x - START[0], y - START[1]) < 0.1 and abs(th - START[2]) < 0.05


def test_compute_path_to_pose(robot: Ros2) -> None:
    got = robot.run_json("ros2_robot_probe.py", "plan", *map(str, GOAL[:2]), timeout=300)
    assert got["status"] == 4 and got["error_code"] == 0  # SUCCEEDED, NONE
    assert got["frame"] == "map" and got["n"] >= 2
    rx, ry, _ = got["map_pose"]  # the robot stands still: the path starts where it is
    assert math.hypot(got["first"][0] - rx, got["first"][1] - ry) < 0.01
    assert got["last"] == pytest.approx(list(GOAL[:2]), abs=1e-6)


def test_make_plan_and_clear_costmaps(robot: Ros2) -> None:
    got = robot.run_json("ros2_robot_probe.py", "services", *map(str, GOAL[:2]), timeout=300)
    assert got["n"] >= 2 and got["last"] == pytest.approx(list(GOAL[:2]), abs=1e-6), got
    assert got["cleared"]


def test_a_twist_from_outside_moves_the_robot(robot: Ros2) -> None:
    """/base_cmd_vel from another process reaches the driver (an outside input of the lockstep
    robot, applied at its next step); the robot's own twists come back over DDS and are
    dropped (counted as own_dropped), not applied twice."""
    got = robot.run_json("ros2_robot_probe.py", "drive", timeout=300)
    assert got["moved"] >= 0.2
    assert got["speed"] == pytest.approx(0.3, abs=0.1)


def test_navigate_to_pose(robot: Ros2) -> None:
    got = robot.run_json("ros2_robot_probe.py", "navigate", *map(str, GOAL), timeout=600)
    assert got["status"] == 4 and got["error_code"] == 0, got  # SUCCEEDED
    assert got["feedback"] >= 10 and got["frame"] == "map"
    fx, fy = got["first_pose"]
    straight = math.hypot(GOAL[0] - fx, GOAL[1] - fy)
    assert got["first_distance"] >= straight - 0.1  # along the plan, from the robot
    assert got["last_distance"] < 0.2
    assert got["last_time"] > got["first_time"] >= 0.0
    x, y, th = got["map_pose"]  # the robot's pose by TF once the result came
    assert math.hypot(x - GOAL[0], y - GOAL[1]) <= XY_TOLERANCE + 0.02, got
    assert abs(math.atan2(math.sin(th - GOAL[2]), math.cos(th - GOAL[2]))) < 0.06, got


def test_vendor_move_base(robot: Ros2) -> None:
    """The vendor's move_base as a ROS 2 action of the same type (woosh_msgs/action/MoveBase:
    no move_base_msgs wheel exists), on the navigator nav2's goals use."""
    got = robot.run_json("ros2_robot_probe.py", "move_base", *map(str, BACK), timeout=600)
    assert got["status"] == 4 and got["feedback"] >= 10 and got["frame"] == "map", got
    x, y, _ = got["map_pose"]
    assert math.hypot(x - BACK[0], y - BACK[1]) <= XY_TOLERANCE + 0.02, got


def test_without_sim_time_it_is_the_same_robot_said_in_one_line(robot: Ros2) -> None:
    """Without --sim-time, --ros2 runs the lockstep robot too, after one line saying so (in a
    domain of its own, beside the module's robot)."""
    from lowerbase.cli.robot import ROS2_SIM_TIME

    own = ros2_or_skip()
    proc = subprocess.run([str(own.python), "-m", "lowerbase", "robot", "--ros2", "--map",
                           "empty_room", "--duration", "2"],
                          env=own.env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.splitlines()[0] == ROS2_SIM_TIME
    assert "simulated time at 1 x" in proc.stdout and "lowerbase robot: stopped at" in \
        proc.stderr


def test_goal_ends_map_to_ros2_states(robot: Ros2) -> None:
    """actionlib's PREEMPTED has no ROS 2 twin: a goal cancelled by its client ends CANCELED;
    one preempted by another server's goal ends ABORTED (ROS 2 cancels only on request) with
    the reason in error_msg, and that other goal runs to SUCCEEDED."""
    got = robot.run_json("ros2_robot_probe.py", "preempt", timeout=900)
    assert got["cancel_answer"] == 1 and got["cancelled"] == 5, got  # CANCELED
    assert got["preempted"] == 6 and got["preempted_error"] == 9000, got  # ABORTED, UNKNOWN
    assert "a goal of another server" in got["preempted_msg"], got
    assert got["move_base"] == 4, got


def test_step_control(robot: Ros2) -> None:
    """The vendor's /cmd_vel_control (woosh_msgs/action/StepControl) on ROS 2: one
    straight step of 0.5 m ends SUCCEEDED with result 1 at 100 %, /odom 0.5 m on."""
    got = robot.run_json("ros2_robot_probe.py", "steps", "0.5", timeout=600)
    assert got["status"] == 4 and got["result"] == 1 and got["executeMode"] == 1, got
    assert got["percent"] == pytest.approx(100.0) and got["feedback"] > 10, got
    assert got["moved"] == pytest.approx(0.5, abs=0.01), got


def test_exec_task_and_robot_status(robot: Ros2) -> None:
    """A transporting task to R1 through the vendor's exec_task (woosh_msgs/srv/ExecTask), its
    end on /robot_status (transient local), the robot at R1 by TF."""
    got = robot.run_json("ros2_robot_probe.py", "task", "7", "2", timeout=900)
    assert got["success"] and "task 7 accepted" in got["message"], got
    assert got["task_state"] == 7 and got["dest"] == "R1", got  # COMPLETED
    x, y, _ = got["map_pose"]
    assert math.hypot(x - R1[0], y - R1[1]) < 0.1, got


def test_the_example_client_drives_goals_and_a_task(robot: Ros2) -> None:
    """examples/ros2_client.py, a team's own rclpy node (docs/ros2.md): a NavigateToPose goal,
    then a transport task to R1, on the robot's simulated time."""
    done = subprocess.run([str(robot.python), str(ROOT / "examples" / "ros2_client.py"),
                           "--goal", "6.0", "4.0", "0.0", "--mark", "R1", "--timeout", "600"],
                          env=robot.env, cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    [nav] = [json.loads(line[9:]) for line in lines if line.startswith("navigate ")]
    assert nav["status"] == 4 and nav["error_code"] == 0 and nav["feedbacks"] > 0, nav
    statuses = [json.loads(line[13:]) for line in lines if line.startswith("robot_status ")]
    assert statuses[-1]["task_state"] == 7 and statuses[-1]["dest"] == "R1", statuses[-1]
