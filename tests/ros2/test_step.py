"""``lowerbase robot --ros2 --paused``: time moves only on ``/lowerbase/step``, as on ROS 1
(docs/robot.md), from an rclpy client in a process of its own (tests/ros2/ros2_step_probe.py).
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.ros2.conftest import Ros2, ros2_or_skip
from tests.ros2.test_driver import robot_on_ros2

ODOM_RATE = 50  #: [Hz] driver_base's /odom, one per WheelFeedback


@pytest.fixture(scope="module")
def robot() -> Iterator[Ros2]:
    ros2 = ros2_or_skip()
    with robot_on_ros2(ros2, ["--map", "empty_room", "--paused"], "empty_room"):
        yield ros2


def test_step_moves_time_by_what_it_asks(robot: Ros2) -> None:
    """A 2 s step returns when its 2 s have run, and has brought each of their 100 /odom;
    seconds <= 0 are refused; unpaused, time runs and a step is refused."""
    got = robot.run_json("ros2_step_probe.py", "step", "2.0", timeout=300)
    assert got["paused"] is True, got
    assert got["warm"][0] and got["warm"][1] >= got["start"], got
    success, message, ran, until_met = got["step"]
    assert success and message == "ran" and not until_met, got
    assert ran == pytest.approx(2.0, abs=1e-6), got
    assert got["odom"] == got["odom_distinct"] == 2 * ODOM_RATE, got
    assert got["refused"] == [False, "seconds must be within (0, 86400], got -1"], got
    assert got["resumed"][0] and got["resumed"][1].startswith("running at "), got
    assert not got["running"][0] and "runs freely: pause it first" in got["running"][1], got
