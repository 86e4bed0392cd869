"""``lowerbase robot`` black-box, on a real ROS master: the parts come up, the chain from
/base_cmd_vel through driver_base, the bus and the emulator to /odom and the world's /scan and
/amcl_pose works, and Ctrl-C leaves no process behind. Only what a user sees is used: the
command's output, ROS topics (the driver tests' probe node) and the process table."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from lowerbase.robot.master import master_answers
from lowerbase.transport import free_loopback_port
from tests.conftest import ROOT
from tests.driver.conftest import require_ros, ros_master, woosh_msgs_build  # noqa: F401
from tests.driver.test_node_ros import PROBE, Probe

TOPICS = {"/odom": "nav_msgs/Odometry", "/scan": "sensor_msgs/LaserScan",
          "/amcl_pose": "geometry_msgs/PoseWithCovarianceStamped"}


class Robot:
    def __init__(self, env: dict[str, str], log_dir: Path, *extra: str) -> None:
        self.popen = subprocess.Popen(
            [sys.executable, "-m", "lowerbase", "robot", "--map", "empty_room",
             "--log-dir", str(log_dir), *extra],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
            env={**os.environ, **env})
        self.lines: list[str] = []

    def wait_for(self, text: str, timeout: float = 120.0) -> None:
        assert self.popen.stdout is not None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            line = self.popen.stdout.readline()
            if not line:
                break
            self.lines.append(line)
            if text in line:
                return
        self.popen.kill()
        raise AssertionError(f"{text!r} not printed: {self.lines} {self.popen.stderr.read()}")

    def children(self) -> list[int]:
        out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(self.popen.pid)],
                             capture_output=True, text=True)
        return [int(p) for p in out.stdout.split()]

    def ctrl_c(self) -> tuple[int, str, str]:
        self.popen.send_signal(signal.SIGINT)
        out, err = self.popen.communicate(timeout=60)
        return self.popen.returncode, out, err


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _x(stats: dict[str, Any], topic: str) -> float:
    return float(stats[topic]["msg"]["pose"]["pose"]["position"]["x"])


@pytest.mark.ros
@pytest.mark.process
def test_robot_on_a_running_master_drives_and_stops_cleanly(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    robot = Robot(env, tmp_path / "logs", "--without", "navigation", "--without", "tasks")
    probe = None
    try:
        robot.wait_for("ready on ROS master")
        parts = robot.children()
        assert len(parts) == 3  # world, emulate, driver: the master was already there
        script = tmp_path / "probe.py"
        script.write_text(PROBE)
        probe = Probe(script, ros_master.env, TOPICS)
        start = probe.wait_for(lambda s: all(s[t]["count"] >= 1 for t in TOPICS), 60.0,
                               "odom, scan and amcl_pose")
        probe.ask(op="publish", topic="/base_cmd_vel", type="geometry_msgs/Twist",
                  fields={"linear": {"x": 0.3}, "angular": {"z": 0.0}}, rate=20, duration=2.0)
        moved = probe.wait_for(lambda s: _x(s, "/odom") > _x(start, "/odom") + 0.3, 20.0,
                               "/odom moving forward")
        # the world saw the same motion: localization follows the robot across the room
        probe.wait_for(lambda s: _x(s, "/amcl_pose") > _x(start, "/amcl_pose") + 0.25, 20.0,
                       "/amcl_pose following")
        assert moved["/scan"]["msg"]["header"]["frame_id"] == "base_link"
    finally:
        if probe is not None:
            probe.close()
        code, out, err = robot.ctrl_c()
    assert code == 0, err
    assert "lowerbase robot: stopped" in out and "Traceback" not in err
    assert not any(_alive(pid) for pid in parts)
    assert {p.name for p in (tmp_path / "logs").iterdir()} == {
        "world.log", "emulate.log", "driver.log"}


@pytest.mark.ros
@pytest.mark.process
def test_robot_starts_its_own_master_when_none_answers_and_takes_it_down(
        woosh_msgs_build: Path, tmp_path: Path) -> None:  # noqa: F811
    require_ros(("rospy", "rosgraph"))
    uri = f"http://127.0.0.1:{free_loopback_port(socket.SOCK_STREAM)}"
    env = {"ROS_MASTER_URI": uri, "ROS_HOME": str(tmp_path / "ros"),
           "ROS_LOG_DIR": str(tmp_path / "ros" / "log")}
    robot = Robot(env, tmp_path / "logs", "--without", "navigation", "--without", "tasks")
    try:
        robot.wait_for(f"started a ROS master at {uri}")
        robot.wait_for("ready on ROS master")
        assert master_answers(uri)
    finally:
        code, _, err = robot.ctrl_c()
    assert code == 0, err
    assert not master_answers(uri)


def test_errors_before_anything_starts_are_one_line(tmp_path: Path) -> None:
    env = {**os.environ, "ROS_MASTER_URI": "http://192.0.2.1:11311"}  # TEST-NET: no master
    for argv, text in (
            (["--map", "nowhere"], "nowhere"),
            (["--map", "empty_room", "--log-dir", str(tmp_path)],
             "no ROS master answers at http://192.0.2.1:11311")):
        out = subprocess.run([sys.executable, "-m", "lowerbase", "robot", *argv], env=env,
                             capture_output=True, text=True, cwd=ROOT, timeout=60)
        assert out.returncode == 1, out.stderr
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1 and text in lines[0] and lines[0].startswith(
            "lowerbase robot: error:"), out.stderr


SIM_TOPICS = {**TOPICS, "/clock": "rosgraph_msgs/Clock"}
WALL_EPOCH = 1.0e9  #: any wall time (since 1970) is past this; the sim time starts near 0


@pytest.mark.ros
@pytest.mark.process
def test_robot_sim_time_runs_the_graph_on_the_simulated_clock(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    import rosgraph

    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    robot = Robot(env, tmp_path / "logs", "--without", "navigation", "--without", "tasks",
                  "--sim-time", "--speed", "2")
    probe = None
    try:
        robot.wait_for("ready on ROS master")
        master = rosgraph.Master("/simtime_test", master_uri=ros_master.env["ROS_MASTER_URI"])
        assert master.getParam("/use_sim_time") is True
        script = tmp_path / "probe.py"
        script.write_text(PROBE)
        probe = Probe(script, ros_master.env, SIM_TOPICS)
        start = probe.wait_for(lambda s: all(s[t]["count"] >= 1 for t in SIM_TOPICS), 60.0,
                               "clock, odom, scan and amcl_pose")
        clock0 = start["/clock"]["msg"]["clock"]
        later = probe.wait_for(lambda s: s["/clock"]["msg"]["clock"] > clock0 + 2.0, 30.0,
                               "/clock advancing")
        clock1 = later["/clock"]["msg"]["clock"]
        assert 0.0 < clock0 < clock1 < WALL_EPOCH
        # every stamp is sim time: near /clock (50 Hz topics, a little behind), not wall time
        for topic in ("/odom", "/scan"):
            stamp = later[topic]["msg"]["header"]["stamp"]
            assert abs(stamp - clock1) < 2.0, (topic, stamp, clock1)
        # the lidars' 25 Hz is per simulated second (the world's loop runs on /clock): count
        # /scan against /clock over a window of 4 s of /clock
        before = probe.ask(op="stats")
        c0 = before["/clock"]["msg"]["clock"]
        after = probe.wait_for(lambda s: s["/clock"]["msg"]["clock"] > c0 + 4.0, 30.0,
                               "4 s of /clock")
        per_sim_s = ((after["/scan"]["count"] - before["/scan"]["count"])
                     / (after["/clock"]["msg"]["clock"] - c0))
        assert 0.7 * 25 <= per_sim_s <= 1.2 * 25, per_sim_s  # 12.5 paced on wall time at K=2
        probe.ask(op="publish", topic="/base_cmd_vel", type="geometry_msgs/Twist",
                  fields={"linear": {"x": 0.3}, "angular": {"z": 0.0}}, rate=20, duration=2.0)
        moved = probe.wait_for(lambda s: _x(s, "/odom") > _x(start, "/odom") + 0.3, 30.0,
                               "/odom moving forward on sim time")
        probe.wait_for(lambda s: _x(s, "/amcl_pose") > _x(start, "/amcl_pose") + 0.25, 30.0,
                       "/amcl_pose following")
        assert abs(moved["/odom"]["msg"]["header"]["stamp"]
                   - moved["/clock"]["msg"]["clock"]) < 2.0
    finally:
        if probe is not None:
            probe.close()
        code, out, err = robot.ctrl_c()
    assert code == 0, err
    assert "Traceback" not in err
    shown = "".join(robot.lines) + out
    assert "x real time" in out and "/use_sim_time true" in shown
    # the master is left as it was found: no /use_sim_time
    assert not master.hasParam("/use_sim_time")
    # lockstep: driver_base's face is in the robot's process (its lines in the robot's output)
    assert "link ready" in shown and "link lost" not in shown


def test_speed_without_sim_time_is_one_line(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "lowerbase", "robot", "--speed", "3"],
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode != 0
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "--speed K goes with --sim-time" in lines[0], out.stderr


@pytest.mark.parametrize(("args", "says"), [
    (["--camera"], "--camera goes with --sim-time"),
    (["_move_base/recovery_behaviors:=[rotate]"], "NAME:=VALUE arguments go with --ros2")])
def test_lockstep_and_ros2_options_without_them_are_one_line(args: list[str],
                                                              says: str) -> None:
    out = subprocess.run([sys.executable, "-m", "lowerbase", "robot", *args],
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode != 0
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], out.stderr


@pytest.mark.parametrize(("args", "says"), [
    (["--paused"], "--paused goes with --sim-time (real time does not wait)"),
    (["--seed", "2"], "--seed S goes with --sim-time (only a lockstep run repeats)"),
    (["--sim-time", "--seed", "-3"], "argument --seed: '-3': a seed is 0 or more"),
    (["--sim-time", "--robot", "legged", "--camera"], "the legged robot has none"),
    (["--log-dir", "/proc/nope"], "--log-dir /proc/nope: No such file or directory; give a "
     "folder you can write to"),
    (["--log-dir", __file__], "test_robot_ros.py: a file, not a folder; give a folder")])
def test_bad_robot_options_end_in_one_line(args: list[str], says: str) -> None:
    out = subprocess.run([sys.executable, "-m", "lowerbase", "robot", *args],
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode != 0 and "Traceback" not in out.stderr
    assert says in out.stderr.strip().splitlines()[-1], out.stderr


@pytest.mark.ros
@pytest.mark.process
def test_a_second_robot_on_a_master_that_has_one_is_refused_and_sighup_stops_the_first(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    """Issue 22, item 27: a second ``lowerbase robot`` on the same master used to start, say
    ready, and take the first one's node names (ROS shut the first one's nodes down); closing
    the terminal (SIGHUP) left the robot running."""
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    robot = Robot(env, tmp_path / "logs", "--sim-time", "--speed", "max", "--without",
                  "navigation", "--without", "tasks")
    try:
        robot.wait_for("in lockstep on simulated time", timeout=300.0)
        second = subprocess.run([sys.executable, "-m", "lowerbase", "robot", "--map",
                                 "empty_room", "--log-dir", str(tmp_path / "second")],
                                capture_output=True, text=True, cwd=ROOT, timeout=120,
                                env={**os.environ, **env})
        assert second.returncode != 0
        lines = [x for x in second.stderr.splitlines() if x.strip()]
        assert len(lines) == 1 and "has a robot running already" in lines[0] \
            and "/lowerbase_robot" in lines[0], second.stderr
        assert robot.popen.poll() is None  # the first one runs on
    finally:
        robot.popen.send_signal(signal.SIGHUP)
        try:
            out, err = robot.popen.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            robot.popen.kill()
            raise
    assert robot.popen.returncode == 0, err
    assert "lowerbase robot: stopped" in out


@pytest.mark.ros
@pytest.mark.process
def test_a_crashed_part_is_on_robot_status_before_the_robot_stops(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    """Issue 22 item 8: kill -9 of the world; before the robot stops, robot_status (latched)
    says ABNORMAL with the part and its exit code, so a customer's task software sees why."""
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    robot = Robot(env, tmp_path / "logs", "--without", "navigation")
    probe = None
    try:
        robot.wait_for("ready on ROS master")
        script = tmp_path / "probe.py"
        script.write_text(PROBE)
        probe = Probe(script, ros_master.env, {"robot_status": "woosh_msgs/RobotStatus"})
        probe.wait_for(lambda s: s["robot_status"]["count"] >= 1, 60.0, "robot_status")
        world = [p for p in robot.children() if "world" in _args(p)]
        assert len(world) == 1
        os.kill(world[0], signal.SIGKILL)
        status = probe.wait_for(
            lambda s: "world ended (exit code -9)" in s["robot_status"]["msg"]["msg"], 30.0,
            "robot_status naming the crash")["robot_status"]["msg"]
        assert status["robot_state"] == 6  # ABNORMAL (seed 000)
        _, err = robot.popen.communicate(timeout=60)  # it stops by itself
        code = robot.popen.returncode
    finally:
        if probe is not None:
            probe.close()
        if robot.popen.poll() is None:
            robot.ctrl_c()
    assert code == 1
    assert "robot_status reports that world ended" in err, err
    assert "error: world ended (exit code -9)" in err and "Traceback" not in err


def _args(pid: int) -> str:
    out = subprocess.run(["ps", "-o", "args=", "-p", str(pid)], capture_output=True, text=True)
    return out.stdout
