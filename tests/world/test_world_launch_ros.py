"""launch/world.launch (package lowerbase_driver): what roslaunch runs for its arguments
(roslaunch --args), and a real roslaunch on a private master, against `lowerbase emulate
--truth-udp`, that serves /map and publishes /scan."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.conftest import Proc, bus_cli_args, free_udp_port
from tests.driver.conftest import ros_master, woosh_msgs_build  # noqa: F401 (fixtures)

DRIVER_DIR = Path(__file__).resolve().parents[2] / "lowerbase" / "driver"
LAUNCH = DRIVER_DIR / "launch" / "world.launch"
SCRIPT = str(DRIVER_DIR / "scripts" / "world")


def _args(env: dict[str, str], *args: str) -> list[str]:
    out = subprocess.run(["roslaunch", "--args", "world", str(LAUNCH), *args],
                         env={**os.environ, **env}, capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr[-2000:]
    words = out.stdout.split()  # [ENV=...] [python] SCRIPT ARGS
    i = words.index(SCRIPT)
    return words[i - 1:] if i and words[i - 1] == sys.executable else words[i:]


@pytest.mark.ros
def test_the_launch_arguments_become_lowerbase_world_options(ros_master: Any) -> None:  # noqa: F811
    env = ros_master.env
    assert _args(env) == [SCRIPT, "--map", "warehouse", "__name:=world"]
    assert _args(env, "map:=empty_room", "camera:=false", "ground_truth:=true",
                 "truth_udp:=43300", "world_args:=--place charger",
                 f"python:={sys.executable}") == [
        sys.executable, SCRIPT, "--map", "empty_room", "--truth-udp", "43300",
        "--ground-truth", "--no-camera", "--place", "charger", "__name:=world"]


@pytest.mark.ros
@pytest.mark.process
def test_roslaunch_starts_the_world(ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    env = ros_master.env
    truth_port = free_udp_port()
    bus = {"interface": "udp_multicast", "channel": "239.74.163.98", "port": free_udp_port(),
           "hop_limit": 0}
    emulator = Proc(["emulate", *bus_cli_args(bus), "--truth-udp", f"127.0.0.1:{truth_port}"],
                    env)
    launch = subprocess.Popen(
        ["roslaunch", str(LAUNCH), "map:=empty_room", "camera:=false", "ground_truth:=true",
         f"truth_udp:=127.0.0.1:{truth_port}", f"python:={sys.executable}"],
        env={**os.environ, **{k: v for k, v in env.items() if k != "ROS_IP"}},
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        def echo(topic: str) -> dict[str, Any]:
            out = subprocess.run(["rostopic", "echo", "-n", "1", "--noarr", topic],
                                 env={**os.environ, **env}, capture_output=True, text=True,
                                 timeout=60)
            assert out.returncode == 0, out.stderr[-2000:]
            doc: dict[str, Any] = yaml.safe_load(out.stdout.split("\n---")[0])
            return doc

        grid = echo("/map")
        assert grid["header"]["frame_id"] == "map"
        assert grid["info"]["resolution"] == pytest.approx(0.05)
        assert echo("/scan")["header"]["frame_id"] == "base_link"  # the truth reached it
        nodes = subprocess.run(["rosnode", "list"], env={**os.environ, **env},
                               capture_output=True, text=True, timeout=30).stdout.split()
        assert "/world" in nodes
    finally:
        launch.send_signal(2)
        try:
            launch.wait(timeout=20)
        except subprocess.TimeoutExpired:
            launch.kill()
            launch.wait()
        emulator.stop()
