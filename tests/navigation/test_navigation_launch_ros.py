"""launch/navigation.launch (package lowerbase_driver): what roslaunch runs for its arguments
(roslaunch --args), and a real roslaunch on a private master: the node move_base comes up on the
given map (its latched global costmap is that map's size, the map's walls LETHAL) and stops on
Ctrl-C."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from lowerbase.world.maps import load_map
from tests.driver.conftest import ros_master, woosh_msgs_build  # noqa: F401 (fixtures)

DRIVER_DIR = Path(__file__).resolve().parents[2] / "lowerbase" / "driver"
LAUNCH = DRIVER_DIR / "launch" / "navigation.launch"
SCRIPT = str(DRIVER_DIR / "scripts" / "navigation")


def _args(env: dict[str, str], *args: str) -> list[str]:
    out = subprocess.run(["roslaunch", "--args", "move_base", str(LAUNCH), *args],
                         env={**os.environ, **env}, capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr[-2000:]
    words = out.stdout.split()  # [ENV=...] [python] SCRIPT ARGS
    i = words.index(SCRIPT)
    return words[i - 1:] if i and words[i - 1] == sys.executable else words[i:]


@pytest.mark.ros
def test_the_launch_arguments_become_lowerbase_navigation_options(
        ros_master: Any) -> None:  # noqa: F811
    env = ros_master.env
    assert _args(env) == [SCRIPT, "--map", "warehouse", "--rate", "20", "__name:=move_base"]
    assert _args(env, "map:=empty_room", "camera:=false", "rate:=10",
                 "navigation_args:=--profile robot.toml", f"python:={sys.executable}") == [
        sys.executable, SCRIPT, "--map", "empty_room", "--rate", "10", "--no-camera",
        "--profile", "robot.toml", "__name:=move_base"]


@pytest.mark.ros
@pytest.mark.process
def test_roslaunch_starts_move_base_on_the_map(ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    env = {**os.environ, **ros_master.env}
    launch = subprocess.Popen(
        ["roslaunch", str(LAUNCH), "map:=empty_room", "camera:=false",
         f"python:={sys.executable}"],
        env={k: v for k, v in env.items() if k != "ROS_IP"},
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        out = subprocess.run(["rostopic", "echo", "-n", "1",
                              "/move_base/global_costmap/costmap"],
                             env=env, capture_output=True, text=True, timeout=90)
        assert out.returncode == 0, out.stderr[-2000:]
        msg = yaml.safe_load(out.stdout.split("\n---")[0])
        grid = load_map("empty_room")
        info = msg["info"]
        assert (info["width"], info["height"]) == (grid.width, grid.height)
        assert msg["header"]["frame_id"] == "map"
        costs = np.asarray(msg["data"], np.int8).reshape(grid.height, grid.width)
        assert np.array_equal(costs[grid.data == 100], np.full((grid.data == 100).sum(), 100))
        nodes = subprocess.run(["rosnode", "list"], env=env, capture_output=True, text=True,
                               timeout=30).stdout.split()
        assert "/move_base" in nodes
    finally:
        launch.send_signal(2)
        try:
            _, err = launch.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            launch.kill()
            _, err = launch.communicate()
    assert "Traceback" not in err, err[-2000:]
