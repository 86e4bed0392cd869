"""``lowerbase robot --sim-time``: the whole robot in lockstep on one simulated clock, tried from
outside with a user's client (examples/sim_goals.py: /map, make_plan, /move_base goals,
exec_task, robot_status, /lowerbase/step).

The same client against the paused robot twice, once with 16 busy processes beside it (load
>= 16 on 2 cores): the same robot_status sequence, the same goal results and the same final
true pose (the emulator's ground truth, ``--truth``) within 1 mm."""

from __future__ import annotations

import itertools
import math
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import ROOT
from tests.driver.conftest import require_ros, ros_master, woosh_msgs_build  # noqa: F401
from tests.robot.test_robot_ros import Robot

HOG = 16  #: busy processes beside the second run
HOG_LIMIT = 900.0  #: [s] each of them ends by itself after this at the latest


@contextmanager
def cpu_hog(n: int) -> Iterator[None]:
    """``n`` processes spinning on the CPU, bounded in time, stopped on the way out. They run
    at nice 19: the load is theirs (>= n runnable), the robot still gets most of a core, so
    the test takes minutes, not tens (benchmarks/bench_robot_sim.py runs them at nice 0)."""
    code = (f"import os, time\nos.nice(19)\nend = time.monotonic() + {HOG_LIMIT}\n"
            "while time.monotonic() < end: pass")
    hogs = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(n)]
    try:
        yield
    finally:
        for h in hogs:
            h.kill()
        for h in hogs:
            h.wait()


def last_truth(path: Path) -> tuple[float, ...]:
    rows = path.read_text().strip().splitlines()
    return tuple(float(v) for v in rows[-1].split(","))


def one_run(env: dict[str, str], tmp: Path, name: str) -> dict[str, Any]:
    import json

    truth = tmp / f"{name}-truth.csv"
    report = tmp / f"{name}.json"
    robot = Robot(env, tmp / f"{name}-logs", "--map", "warehouse", "--sim-time", "--paused",
                  "--speed", "max", "--truth", str(truth))
    try:
        robot.wait_for("in lockstep on simulated time", timeout=300.0)
        out = subprocess.run(
            [sys.executable, str(ROOT / "examples" / "sim_goals.py"), "--goals", "2",
             "--seed", "3", "--mark", "A2-01", "--step", "--report", str(report)],
            capture_output=True, text=True, env={**os.environ, **env}, timeout=1200)
        assert out.returncode == 0, (out.stdout[-3000:], out.stderr[-3000:])
    finally:
        code, _, err = robot.ctrl_c()
    assert code == 0, err[-3000:]
    assert "Traceback" not in err
    result = json.loads(report.read_text())
    result["truth"] = last_truth(truth)
    return result


@pytest.mark.ros
@pytest.mark.process
def test_the_same_client_gives_the_same_robot_on_an_idle_and_on_a_loaded_host(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    require_ros(("rospy", "actionlib", "tf2_ros", "nav_msgs.srv", "std_srvs.srv",
                 "lowerbase_sim_msgs.srv"))
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    idle = one_run(env, tmp_path, "idle")
    t0 = time.monotonic()
    with cpu_hog(HOG):
        loaded = one_run(env, tmp_path, "loaded")
        load = os.getloadavg()[0]
    print(f"loaded run: {time.monotonic() - t0:.0f} s wall, load {load:.1f}")
    assert [g["state"] for g in idle["goals"]] == [3, 3]
    assert idle["task"]["final_task_state"] == 7
    def goals(run: dict[str, Any]) -> list[tuple[Any, ...]]:
        return [(tuple(g["goal"]), g["state"], g["text"]) for g in run["goals"]]

    assert goals(loaded) == goals(idle)
    for key in ("task", "robot_status"):
        assert loaded[key] == idle[key], key
    t_idle, t_loaded = idle["truth"], loaded["truth"]
    assert math.hypot(t_loaded[1] - t_idle[1], t_loaded[2] - t_idle[2]) <= 0.001, \
        (t_idle, t_loaded)
    assert abs(t_loaded[3] - t_idle[3]) <= 0.001


STAMPS = '''
import json, sys, time
import rospy
from rosgraph_msgs.msg import Clock
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, LaserScan
from actionlib_msgs.msg import GoalStatusArray
from lowerbase_sim_msgs.srv import Step
# disable_rostime: without it rospy follows /clock itself (use_sim_time is true), with a
# queue of 1 that the /clock subscriber below shares: a busy host then drops /clock messages
# that arrive together (rospy.impl.simtime), which are what this counts
rospy.init_node("stamps", anonymous=True, disable_rostime=True)
got = {"/clock": [], "/imu/data_raw": [], "/odom": [], "/scan": [], "/move_base/status": []}
def keep(topic, stamp):
    got[topic].append(stamp.to_sec())
subs = [rospy.Subscriber("/clock", Clock, lambda m: keep("/clock", m.clock), queue_size=10000),
        rospy.Subscriber("/imu/data_raw", Imu, lambda m: keep("/imu/data_raw", m.header.stamp),
                         queue_size=10000),
        rospy.Subscriber("/odom", Odometry, lambda m: keep("/odom", m.header.stamp),
                         queue_size=10000),
        rospy.Subscriber("/scan", LaserScan, lambda m: keep("/scan", m.header.stamp),
                         queue_size=10000),
        rospy.Subscriber("/move_base/status", GoalStatusArray,
                         lambda m: keep("/move_base/status", m.header.stamp), queue_size=10000)]
rospy.wait_for_service("/lowerbase/step", timeout=60)
step = rospy.ServiceProxy("/lowerbase/step", Step)
while any(s.get_num_connections() == 0 for s in subs):
    time.sleep(0.05)
t0 = step(seconds=1.0, until="").sim_time  # the link comes up; counted from here by stamp
# 50 ms of simulated time per call, and the next call only once the /clock of its end has
# arrived: at most a few messages are ever in flight, whatever the host's load, so no queue
# of either side can overflow (a 5 s call at once leaves it to the host's speed); a message
# lost shows in the counts below, not as a wait
STEP = 0.05
def after(topic):
    return [t for t in got[topic] if t > t0 + 1e-6]
for k in range(1, round(float(sys.argv[2]) / STEP) + 1):
    res = step(seconds=STEP, until="")
    end = time.monotonic() + 60.0
    while time.monotonic() < end and max(got["/clock"], default=0.0) < res.sim_time - 1e-6:
        time.sleep(0.002)
time.sleep(1.0)  # the last messages of the slower topics
got = {topic: after(topic) for topic in got}
json.dump({"got": got, "sim_time": res.sim_time}, open(sys.argv[1], "w"))
'''


@pytest.mark.ros
@pytest.mark.process
def test_topics_come_at_their_rates_of_simulated_time_with_distinct_rising_stamps(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    """/clock and /imu/data_raw at 100 Hz, /odom at 50 Hz and /scan at 25 Hz of simulated
    time, each stamp later than the one before: over 5 simulated seconds of /lowerbase/step
    (stepped 50 ms at a time, counted by stamp: no queue can overflow on a busy host). And
    actionlib's /move_base/status at its 5 Hz: its timer thread is woken once per status
    period, not at every step (lockstep.RosTime), and none is skipped (it runs on its own,
    beside the steps: one more or less at the window's ends)."""
    import json

    require_ros(("rospy", "lowerbase_sim_msgs.srv"))
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    script, out = tmp_path / "stamps.py", tmp_path / "stamps.json"
    script.write_text(STAMPS)
    robot = Robot(env, tmp_path / "logs", "--map", "warehouse", "--sim-time", "--paused",
                  "--speed", "2")
    try:
        robot.wait_for("in lockstep on simulated time", timeout=300.0)
        run = subprocess.run([sys.executable, str(script), str(out), "5"], capture_output=True,
                             text=True, env={**os.environ, **env}, timeout=300)
        assert run.returncode == 0, run.stderr[-3000:]
    finally:
        code, _, err = robot.ctrl_c()
    assert code == 0, err[-3000:]
    got = json.loads(out.read_text())["got"]
    for topic, rate in (("/clock", 100), ("/imu/data_raw", 100), ("/odom", 50),
                        ("/scan", 25)):
        stamps = got[topic]
        assert all(b > a for a, b in itertools.pairwise(stamps)), (topic, stamps[:20])
        assert abs(len(stamps) - 5 * rate) <= 2, (topic, len(stamps))
    status = got["/move_base/status"]
    assert all(b > a for a, b in itertools.pairwise(status)), status
    assert abs(len(status) - 5 * 5) <= 2, status


LEGGED = '''
import json, math, sys, time
import rospy
from std_srvs.srv import Trigger
from lowerbase_legged_msgs.msg import RobotState, Waypoint
from lowerbase_legged_msgs.srv import SetWaypoints
from lowerbase_sim_msgs.srv import Step
rospy.init_node("legged_probe", anonymous=True)
states = []
rospy.Subscriber("/robot_state", RobotState, states.append, queue_size=100000)
rospy.wait_for_service("/lowerbase/step", timeout=60)
step = rospy.ServiceProxy("/lowerbase/step", Step)
walk = rospy.ServiceProxy("/legged_driver/walk", Trigger)
mission = rospy.ServiceProxy("/planning/set_waypoints", SetWaypoints)
def settle():
    time.sleep(0.5)  # wall time: the paused robot's last messages arrive
step(seconds=2.0, until="")
settle()
answer = walk()
for _ in range(40):
    step(seconds=0.5, until="")
    settle()
    if states and states[-1].state == RobotState.IN_CONTROL:
        break
walking_at = states[-1].state
set_wp = mission(waypoints=[Waypoint(frame="odom", x=1.5, y=0.0)], repetition=1,
                 current_index=0)
n0 = len(states)
res = step(seconds=30.0, until="walked")
settle()
walked = states[n0 - 1:]
path = sum(math.hypot(b.base_pos[0] - a.base_pos[0], b.base_pos[1] - a.base_pos[1])
           for a, b in zip(walked, walked[1:]))
said = sum(math.hypot(*a.base_lin_vel[:2]) * 0.02 for a in walked[:-1])
json.dump({"answer": answer.success, "walking": walking_at, "mission": set_wp.success,
           "until_met": res.until_met, "end": list(walked[-1].base_pos), "path": path,
           "said": said, "n": len(walked)}, open(sys.argv[1], "w"))
'''


@pytest.mark.ros
@pytest.mark.process
def test_the_legged_robot_walks_in_lockstep_as_far_as_robot_state_says(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    """``--robot legged --sim-time --paused``: ~walk brings it IN_CONTROL, a one-waypoint
    mission 1.5 m ahead is walked (step until "walked"), and the distance its base moved is
    the one robot_state's velocity integrates to (the field trial's body walked at 18-72 % of
    the velocity robot_state reported while its emulator fell behind the wall clock)."""
    import json

    require_ros(("rospy", "lowerbase_legged_msgs.msg", "lowerbase_sim_msgs.srv"))
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    script, out = tmp_path / "legged.py", tmp_path / "legged.json"
    script.write_text(LEGGED)
    robot = Robot(env, tmp_path / "logs", "--robot", "legged", "--sim-time", "--paused",
                  "--speed", "max")
    try:
        robot.wait_for("in lockstep on simulated time", timeout=300.0)
        run = subprocess.run([sys.executable, str(script), str(out)], capture_output=True,
                             text=True, env={**os.environ, **env}, timeout=600)
        assert run.returncode == 0, run.stderr[-3000:]
    finally:
        code, _, err = robot.ctrl_c()
    assert code == 0, err[-3000:]
    got = json.loads(out.read_text())
    assert got["answer"] and got["walking"] == 7 and got["mission"], got  # IN_CONTROL
    assert got["until_met"], got
    assert math.hypot(got["end"][0] - 1.5, got["end"][1]) < 0.3, got
    assert got["path"] > 1.0 and abs(got["said"] - got["path"]) <= 0.05 * got["path"], got
