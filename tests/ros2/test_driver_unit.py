"""The ROS-free parts of ``lowerbase driver --ros2`` (run in the ROS 1 venv, without rclpy)."""

from __future__ import annotations

import importlib.util

import pytest

from lowerbase.cli import main
from lowerbase.driver.ros2_node import (
    DEFAULTS,
    LOOPBACK_PROFILE,
    flatten,
    loopback_only,
    ros2_arguments,
    unflatten,
)
from lowerbase.driver.settings import load_settings


def test_ros1_arguments_become_ros2_ones() -> None:
    assert ros2_arguments(["_publish_tf:=false", "_topics/odom:=/o", "__name:=base",
                           "__ns:=/r1", "odom:=odom2", "__log:=/tmp/x"]) == [
        "-p", "publish_tf:=false", "-p", "topics.odom:=/o", "-r", "__node:=base",
        "-r", "__ns:=/r1", "-r", "odom:=odom2"]


def test_defaults_round_trip_as_dotted_parameters() -> None:
    import yaml

    tree = yaml.safe_load(DEFAULTS.read_text())
    flat = flatten(tree)
    assert flat["topics.odom"] == "/odom" and flat["odometry_noise.scale_error"] == 0.01
    assert "ekf_noise" not in flat  # an empty dict declares nothing
    back = unflatten(flat)
    settings, config = load_settings(back)
    assert settings.topics["odom"] == "/odom" and config.command_rate == 50.0


def test_without_rclpy_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    if importlib.util.find_spec("rclpy") is not None:
        pytest.skip("rclpy is importable here (the ROS 2 venv)")
    code = main(["driver", "--ros2", "-i", "virtual", "-c", "x"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0
    assert [line for line in err if "error" in line] == [
        line for line in err if "ROS 2 is not importable" in line and "make ros2" in line]


def test_legged_is_not_on_ros2_yet(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["driver", "--ros2", "--robot", "legged", "-i", "virtual", "-c", "x"]) == 1
    assert "--ros2 is for the wheeled robot so far" in capsys.readouterr().err


def test_loopback_profile_unless_asked_otherwise() -> None:
    assert LOOPBACK_PROFILE.is_file()
    for given in ({}, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOCALHOST_ONLY": "1"}):
        env = dict(given)
        assert loopback_only(env)
        assert env == {"FASTDDS_DEFAULT_PROFILES_FILE": str(LOOPBACK_PROFILE),
                       "ROS_AUTOMATIC_DISCOVERY_RANGE": "SYSTEM_DEFAULT"}
    subnet = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert not loopback_only(subnet) and subnet == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    own = {"FASTDDS_DEFAULT_PROFILES_FILE": "/x.xml"}
    assert not loopback_only(own)
    assert own == {"FASTDDS_DEFAULT_PROFILES_FILE": "/x.xml",
                   "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
