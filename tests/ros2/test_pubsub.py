"""Two rclpy processes of the ROS 2 venv talk woosh_msgs over Fast DDS on loopback."""

from __future__ import annotations

import subprocess

import pytest

from tests.ros2.conftest import Ros2


def test_battery_between_processes(ros2: Ros2) -> None:
    pub = ros2.popen("ros2_pubsub.py", "pub", "/battery")
    try:
        got = ros2.run_json("ros2_pubsub.py", "sub", "/battery", timeout=60)
    finally:
        pub.terminate()
        try:
            pub.wait(timeout=10)
        except subprocess.TimeoutExpired:  # a stuck publisher
            pub.kill()
            pub.wait()
    assert got == {"percentage": 87, "voltage": pytest.approx(51.5), "charge_mode": 1,
                   "bms_status": 0xDEADBEEF, "frame_id": "battery", "auto_mode": 1}
