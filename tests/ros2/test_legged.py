"""``lowerbase robot --robot legged --sim-time --ros2`` (the legged robot in lockstep, on ROS 2)
with rclpy clients in processes of their own (tests/ros2/ros2_legged_probe.py).

One robot serves the module, at ``--speed 1``: robot_state carries no stamp, so its rate is
measured in the simulated time at which the robot sent each message (the last /clock it sent
before, by their source timestamps), which holds however late a busy host lets the probe read.
The tests run in file order; the one that walks comes last.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.ros2.conftest import Ros2, ros2_or_skip
from tests.ros2.test_driver import robot_on_ros2

IN_CONTROL, STANDING_MODE = 7, 6  #: RobotState's state values
JOY, VEL_CMD = 0, 1  #: RobotState's joy_listen_type values


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Ros2, Path]]:
    ros2 = ros2_or_skip()
    home = tmp_path_factory.mktemp("ros_home")  # set_map's PCD files go to $ROS_HOME/maps
    env = {**ros2.env, "ROS_HOME": str(home)}
    with robot_on_ros2(ros2, ["--robot", "legged", "--sim-time", "--speed", "1"],
                       "legged driver", env=env):
        yield ros2, home


def test_the_ros1_interface_on_ros2(robot: tuple[Ros2, Path]) -> None:
    """The names and types of the ROS 1 legged driver. robot_state is not latched there
    (nor is anything else of the legged face), so it is volatile here."""
    got = robot[0].run_json("ros2_legged_probe.py", "interface", timeout=300)
    assert got["topics"] == {"/robot_state": ["lowerbase_legged_msgs/msg/RobotState"],
                             "/clock": ["rosgraph_msgs/msg/Clock"],
                             "/cmd_vel": ["geometry_msgs/msg/Twist"]}, got
    assert "lowerbase_robot" in got["cmd_vel_subscribers"], got
    assert got["services"] == {
        "/planning/set_waypoints": ["lowerbase_legged_msgs/srv/SetWaypoints"],
        "/planning/get_waypoints": ["lowerbase_legged_msgs/srv/GetWaypoints"],
        "/planning/append_waypoint": ["lowerbase_legged_msgs/srv/AppendWaypoint"],
        "/set_map": ["lowerbase_legged_msgs/srv/SetLaserMap"],
        "/set_listen": ["lowerbase_legged_msgs/srv/SetListen"],
        **{f"/legged_driver/{n}": ["std_srvs/srv/Trigger"]
           for n in ("walk", "stand", "sit", "stop_waypoints")}}, got
    assert got["state_qos"] == ["RELIABLE", "VOLATILE"], got


def test_robot_state_at_50_hz_of_clock_time(robot: tuple[Ros2, Path]) -> None:
    got = robot[0].run_json("ros2_legged_probe.py", "topics", timeout=300)
    assert got["state_rate"] == pytest.approx(50.0, rel=0.01) and got["span"] > 5.0, got
    assert got["actuators"] == 12, got
    assert got["clock_last"] > got["clock_first"] and got["clock_backwards"] == 0, got


def test_services_from_rclpy(robot: tuple[Ros2, Path]) -> None:
    """planning/*, ~stop_waypoints, set_listen (robot_state's joy_listen_type follows) and
    set_map (its PCD file written) answer an rclpy client."""
    ros2, home = robot
    got = ros2.run_json("ros2_legged_probe.py", "services", str(home / "maps"), timeout=300)
    assert got["empty"] == [False, "waypoint list is empty"], got
    assert got["set"] == [True, "set waypoint success"], got
    assert got["get"] == [True, 1, 1], got
    assert got["stopped"], got
    assert got["listen"][0] and got["closed"], got
    assert got["joy"] == [VEL_CMD, JOY, VEL_CMD], got
    assert got["map"] == [True, "Map saved."], got
    assert (home / "maps" / "probe_map.pcd").is_file()


def test_walk_and_cmd_vel_move_the_body(robot: tuple[Ros2, Path]) -> None:
    """~walk brings it IN_CONTROL; /cmd_vel at 0.3 m/s from another process moves the base
    0.3 m ahead, as far as robot_state's own velocity integrates to; ~stand stops it."""
    got = robot[0].run_json("ros2_legged_probe.py", "walk", timeout=600)
    assert got["walk"][0] and got["walk"][1].endswith("-> IN_CONTROL"), got
    assert got["moved"] >= 0.3 and got["heading_x"] > 0.25, got  # ahead: +x of odom
    assert got["speed"] == pytest.approx(0.3, abs=0.1), got
    assert got["path"] > 0.25 and abs(got["said"] - got["path"]) <= 0.05 * got["path"], got
    assert got["stand"][0] and got["stand"][1].endswith("-> STANDING_MODE"), got
    assert got["state"] == STANDING_MODE, got
