"""``lowerbase robot --foxglove HOST:PORT`` on a real ROS master: the recorder child serves the
robot's ROS topics (and the bus's frames) to a Foxglove WebSocket client, which subscribes and
decodes /odom, /scan and the latched /map with the ros1 schemas the server advertises (rosbags
builds the types from the schema text alone). The client waits for messages, never for a time.
Without ROS: the plan and a busy port's one-line error."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.msg import get_types_from_msg

from lowerbase.robot.plan import RobotOptions, robot_plan
from lowerbase.transport import free_loopback_port
from tests.conftest import ROOT
from tests.driver.conftest import ros_master, woosh_msgs_build  # noqa: F401
from tests.recording.foxglove_client import FoxgloveClient
from tests.robot.test_robot_ros import Robot


def _decode(channel: dict[str, Any], payload: bytes) -> Any:
    """A ros1 payload decoded with nothing but the channel's advertised schema."""
    assert (channel["encoding"], channel["schemaEncoding"]) == ("ros1", "ros1msg")
    pkg, name = channel["schemaName"].split("/")
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(channel["schema"], f"{pkg}/msg/{name}"))
    return store.deserialize_ros1(payload, f"{pkg}/msg/{name}")


@pytest.mark.ros
@pytest.mark.process
def test_robot_foxglove_serves_ros_topics(ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    port = free_loopback_port(socket.SOCK_STREAM)
    robot = Robot(env, tmp_path / "logs", "--without", "navigation", "--without", "tasks",
                  "--foxglove", f"127.0.0.1:{port}")
    client = None
    try:
        robot.wait_for("ready on ROS master")
        assert len(robot.children()) == 4  # world, recorder, emulate, driver
        assert any(f"ws://127.0.0.1:{port}" in line for line in robot.lines)
        client = FoxgloveClient(f"ws://127.0.0.1:{port}")
        wanted = ("/odom", "/scan", "/map", "/can/frames")
        client.pump_until(lambda: all(t in client.channels for t in wanted), 60.0)
        # /map was published once, before this client came: the latched message is sent again
        client.subscribe(*wanted)
        client.pump_until(lambda: all(client.messages.get(t) for t in wanted), 60.0)
        channels = dict(client.channels)
        got = {t: client.messages[t][-1][1] for t in wanted}
    finally:
        if client is not None:
            client.close()
        code, out, err = robot.ctrl_c()
    assert code == 0 and "lowerbase robot: stopped" in out, err
    recorder = (tmp_path / "logs" / "recorder.log").read_text()
    assert "Traceback" not in recorder
    assert "live view" not in (tmp_path / "logs" / "emulate.log").read_text()  # one server

    odom = _decode(channels["/odom"], got["/odom"])
    assert channels["/odom"]["schemaName"] == "nav_msgs/Odometry"
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_link")
    assert odom.header.seq >= 1 and len(odom.pose.covariance) == 36
    scan = _decode(channels["/scan"], got["/scan"])
    assert channels["/scan"]["schemaName"] == "sensor_msgs/LaserScan"
    assert scan.header.frame_id == "base_link" and len(scan.ranges) > 100
    assert scan.angle_max > scan.angle_min
    grid = _decode(channels["/map"], got["/map"])
    assert grid.header.frame_id == "map" and grid.info.width * grid.info.height == \
        len(grid.data) > 0
    assert channels["/can/frames"]["schemaName"] == "can_msgs/Frame"


def test_robot_plan_serves_from_the_recorder_alone() -> None:
    specs = {s.name: list(s.argv) for s in robot_plan(
        RobotOptions(map="empty_room", foxglove="127.0.0.1:9000", bus_port=1, truth_port=2))}
    assert list(specs) == ["world", "recorder", "emulate", "driver", "navigation", "tasks"]
    assert specs["recorder"][3:5] == ["--foxglove", "127.0.0.1:9000"]  # no MCAP file
    assert "--foxglove" not in specs["emulate"]
    both = {s.name: list(s.argv) for s in robot_plan(
        RobotOptions(map="empty_room", foxglove="127.0.0.1:9000", mcap="r.mcap"))}
    assert both["recorder"][3].endswith("r.mcap") and "--foxglove" in both["recorder"]


def test_robot_foxglove_busy_port_is_one_line(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        run = subprocess.run(
            [sys.executable, "-m", "lowerbase", "robot", "--map", "empty_room", "--log-dir",
             str(tmp_path), "--foxglove", f"127.0.0.1:{port}"],
            capture_output=True, text=True, cwd=ROOT, timeout=60,
            env={**os.environ, "ROS_MASTER_URI": "http://127.0.0.1:1"})
    assert run.returncode != 0
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and f"127.0.0.1:{port}: cannot listen" in lines[0], run.stderr
    assert "started a ROS master" not in run.stdout and not list(tmp_path.iterdir())
