"""``lowerbase robot --sim-time``: the whole robot in lockstep, as users run it.

- ``whole robot, our parts only``: this process becomes the lockstep robot (warehouse, amcl,
  navigation, tasks) on a rosmaster of the benchmark's own and drives move_base goals between
  the map's storage places, no client on ROS; simulated seconds per wall second.
- ``with a rospy client``: ``lowerbase robot --sim-time --speed max`` and
  ``examples/sim_goals.py`` free-running (subscribed to /map, /amcl_pose, robot_status;
  make_plan; goals through actionlib): the factor the robot achieved (its
  /lowerbase/sim_status) and the goals reached.
- ``paused, with 16 busy processes``: the same goals with ``--paused`` and the client's
  ``--step``, once idle and once beside 16 processes spinning at nice 0: the final true poses
  (``--truth``) must be identical; the wall time of each.
- ``legged robot alone``: this process becomes the legged lockstep robot (its lower computer,
  driver core and ROS face, no client on ROS), walks (~walk) and trots for
  :data:`LEGGED_SECONDS`: simulated seconds per wall second (issue 21's target >= 20 x).
- ``legged robot trotting``: ``lowerbase robot --robot legged --sim-time --paused --speed max``;
  a rospy client subscribed to robot_state calls ~walk, steps until IN_CONTROL, gives a
  waypoint 100 m ahead and times one ``/lowerbase/step`` of :data:`LEGGED_SECONDS`: the 12
  actuators' 24,000 frames per simulated second, the driver and its face, all the way.

Needs ROS (rosmaster, rospy); skipped without it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.common import Row

ROOT = Path(__file__).resolve().parents[1]
GROUP = "robot --sim-time"
LEGGED_SECONDS = 30.0  #: simulated seconds of trotting timed (the quick run: a third)
LEGGED_CLIENT = """
import json, sys, time
import rospy
from std_srvs.srv import Trigger
from lowerbase_legged_msgs.msg import RobotState, Waypoint
from lowerbase_legged_msgs.srv import SetWaypoints
from lowerbase_sim_msgs.srv import Step
rospy.init_node("legged_bench", anonymous=True)
states = []
rospy.Subscriber("/robot_state", RobotState, states.append, queue_size=100000)
rospy.wait_for_service("/lowerbase/step", timeout=60)
step = rospy.ServiceProxy("/lowerbase/step", Step)
step(seconds=1.0, until="")
rospy.ServiceProxy("/legged_driver/walk", Trigger)()
for _ in range(40):
    step(seconds=0.5, until="")
    time.sleep(0.3)
    if states and states[-1].state == RobotState.IN_CONTROL:
        break
ok = rospy.ServiceProxy("/planning/set_waypoints", SetWaypoints)(
    waypoints=[Waypoint(frame="odom", x=100.0, y=0.0)], repetition=1, current_index=0).success
n0, t0 = len(states), time.perf_counter()
step(seconds=float(sys.argv[2]), until="")
wall = time.perf_counter() - t0
time.sleep(1.0)
walked = [s for s in states[n0:] if s.state == RobotState.IN_CONTROL]
json.dump({"wall": wall, "mission": ok, "states": len(states) - n0, "trotting": len(walked),
           "x": states[-1].base_pos[0] - states[n0 - 1].base_pos[0]}, open(sys.argv[1], "w"))
"""


def _free_port() -> int:
    from lowerbase.transport import free_loopback_port

    return int(free_loopback_port())


class _Master:
    def __init__(self) -> None:
        self.port = _free_port()
        self.uri = f"http://127.0.0.1:{self.port}"
        self.proc = subprocess.Popen(["rosmaster", "--core", "-p", str(self.port)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     env={**os.environ, "ROS_IP": "127.0.0.1"})
        import rosgraph

        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            try:
                rosgraph.Master("/bench", master_uri=self.uri).getPid()
                return
            except Exception:
                time.sleep(0.1)
        raise RuntimeError("rosmaster did not come up")

    def env(self) -> dict[str, str]:
        return {**os.environ, "ROS_MASTER_URI": self.uri, "ROS_IP": "127.0.0.1"}

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(10)


def _in_process(master: _Master, goals: int) -> tuple[float, float, int]:
    """(simulated s, wall s, goals reached) of the lockstep robot alone in a subprocess."""
    code = f"""
import json, time
from lowerbase.robot.simrun import init_rospy
from lowerbase.robot.lockstep import LockstepRobot, LockstepOptions
from lowerbase.tasks.local_nav import NodeNavigation
from lowerbase.world.places import load_places
from lowerbase.world.maps import load_map
rospy = init_rospy()
r = LockstepRobot(LockstepOptions(map="warehouse"), rospy)
r.advertise()
r.run_periods(400)
places = sorted(load_places("warehouse", load_map("warehouse")).storage.values())
nav = NodeNavigation(r.navigation)
t0, s0, ok = time.perf_counter(), r.now, 0
for i in range({goals}):
    nav.send_goal(places[(5 * i) % len(places)], now=r.now)
    r.run_periods(200)
    r.run_periods(round(120 / r.dt), r.navigation_idle)
    ok += r.navigation.navigator.state.name == "SUCCEEDED"
print(json.dumps([r.now - s0, time.perf_counter() - t0, ok]))
r.shutdown(); rospy.signal_shutdown("done")
"""
    sim, wall, ok = _result(master, code, "the lockstep robot")
    return float(sim), float(wall), int(ok)


def _result(master: _Master, code: str, what: str) -> list[Any]:
    """The JSON list ``code`` prints, run as a child process on ``master``."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=master.env(), cwd=ROOT, timeout=3600)
    # the faces print their stop lines after the result: take the result's own line
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("[") and ln.endswith("]")]
    if not lines:
        raise RuntimeError(f"{what} gave no result: {out.stderr[-2000:]}")
    return list(json.loads(lines[-1]))


def _robot(master: _Master, tmp: Path, *extra: str,
           robot: tuple[str, ...] = ("--map", "warehouse")) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-m", "lowerbase", "robot", *robot,
                             "--sim-time", "--log-dir", str(tmp / "logs"), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=master.env(), cwd=ROOT)
    assert proc.stdout is not None
    for line in proc.stdout:
        if "in lockstep on simulated time" in line:
            return proc
    raise RuntimeError(f"the robot did not start: {proc.stderr.read() if proc.stderr else ''}")


def _stop(proc: subprocess.Popen[str]) -> str:
    proc.send_signal(2)
    out, _ = proc.communicate(timeout=120)
    return out


def _legged_in_process(master: _Master, seconds: float) -> Row:
    code = f"""
import json, time
from lowerbase.protocol.legged import LocomotionState as S
from lowerbase.robot.lockstep import LockstepOptions
from lowerbase.robot.lockstep_legged import LeggedLockstep
from lowerbase.robot.simrun import init_rospy
rospy = init_rospy()
r = LeggedLockstep(LockstepOptions(), rospy)
r.advertise()
r.node.goals.set(S.IN_CONTROL)
r.run_periods(5000)
state = int(r.loop.driver.state)
t0, x0 = time.perf_counter(), r.loop.lower.body.x
for _ in range({round(seconds * 20)}):  # cmd_vel at 20 Hz, as a teleop would
    r.node.core.set_velocity(0.5, 0.0, 0.2)
    r.run_periods(50)
print(json.dumps([time.perf_counter() - t0, state, int(r.loop.driver.state),
                  r.loop.lower.body.x - x0]))
r.shutdown(); rospy.signal_shutdown("done")
"""
    wall, before, after, dx = _result(master, code, "the legged lockstep robot")
    if before != after or after != 7:
        raise RuntimeError(f"the legged robot did not trot throughout (state {before} -> "
                           f"{after})")
    return Row(GROUP, "legged robot alone, trotting, 12 actuators at 1 kHz", seconds / wall,
               "x", f"{seconds:g} simulated s IN_CONTROL in {wall:.2f} s wall (driver core, "
               f"robot_state at 50 Hz, /clock; nobody subscribed); the base {dx:.1f} m on; "
               f"load {os.getloadavg()[0]:.1f}")


def _legged(master: _Master, tmp: Path, seconds: float) -> Row:
    robot = _robot(master, tmp / "legged", "--paused", "--speed", "max",
                   robot=("--robot", "legged"))
    script, report = tmp / "legged_client.py", tmp / "legged.json"
    script.write_text(LEGGED_CLIENT)
    try:
        run = subprocess.run([sys.executable, str(script), str(report), str(seconds)],
                             capture_output=True, text=True, env=master.env(), timeout=3600)
        if run.returncode != 0:
            raise RuntimeError(f"the legged client failed: {run.stderr[-2000:]}")
    finally:
        _stop(robot)
    got = json.loads(report.read_text())
    return Row(GROUP, "legged robot trotting, 12 actuators at 1 kHz, a rospy client",
               seconds / got["wall"], "x",
               f"one /lowerbase/step of {seconds:g} simulated s in {got['wall']:.2f} s wall; "
               f"robot_state {got['states']} messages ({got['trotting']} IN_CONTROL), the "
               f"base {got['x']:.1f} m ahead; load {os.getloadavg()[0]:.1f}")


def _client(master: _Master, report: Path, goals: int, *extra: str) -> dict[str, Any]:
    subprocess.run([sys.executable, str(ROOT / "examples" / "sim_goals.py"), "--goals",
                    str(goals), "--mark", "", "--report", str(report), *extra],
                   capture_output=True, text=True, env=master.env(), timeout=7200)
    return dict(json.loads(report.read_text()))


def run(quick: bool = False) -> list[Row]:
    if shutil.which("rosmaster") is None:
        print("# bench_robot_sim: skipped (no rosmaster)", file=sys.stderr)
        return []
    goals = 4 if quick else 20
    rows: list[Row] = []
    master = _Master()
    tmp = Path(tempfile.mkdtemp(prefix="bench-robot-sim-"))
    try:
        rows.append(_legged_in_process(master, LEGGED_SECONDS / (3 if quick else 1)))
        rows.append(_legged(master, tmp, LEGGED_SECONDS / (3 if quick else 1)))
        sim, wall, ok = _in_process(master, 3 if quick else 10)
        rows.append(Row(GROUP, "whole robot, our parts only, --speed max", sim / wall, "x",
                        f"{sim:.0f} simulated s of move_base goals in {wall:.1f} s wall; "
                        f"{ok} goals reached; load {os.getloadavg()[0]:.1f}"))
        robot = _robot(master, tmp / "free", "--speed", "max")
        rep = _client(master, tmp / "free.json", goals)
        s0, s1 = rep["sim_time"]
        wall = rep["wall_time"][1] - rep["wall_time"][0]
        _stop(robot)
        reached = sum(g["state"] == 3 for g in rep["goals"])
        rows.append(Row(GROUP, "with a rospy client, --speed max", (s1 - s0) / wall, "x",
                        f"examples/sim_goals.py free-running: {reached}/{len(rep['goals'])} "
                        f"goals SUCCEEDED, {s1 - s0:.0f} simulated s in {wall:.0f} s"))
        finals = []
        for hog in (0, 16):
            hogs = [subprocess.Popen([sys.executable, "-c", "import time\nend = "
                                      "time.monotonic() + 3600\nwhile time.monotonic() < end: "
                                      "pass"]) for _ in range(hog)]
            try:
                truth = tmp / f"truth-{hog}.csv"
                robot = _robot(master, tmp / f"step-{hog}", "--speed", "max", "--paused",
                               "--truth", str(truth))
                t0 = time.perf_counter()
                rep = _client(master, tmp / f"step-{hog}.json", goals, "--step")
                wall = time.perf_counter() - t0
                load = os.getloadavg()[0]
                _stop(robot)
            finally:
                for h in hogs:
                    h.kill()
            finals.append(truth.read_text().strip().splitlines()[-1])
            reached = sum(g["state"] == 3 for g in rep["goals"])
            rows.append(Row(GROUP, f"paused + --step, {hog} busy processes beside", wall, "s",
                            f"{reached}/{len(rep['goals'])} goals SUCCEEDED; load {load:.1f}; "
                            f"final true pose {finals[-1]}"))
        rows.append(Row(GROUP, "final true pose identical, idle vs 16 busy processes",
                        float(finals[0] == finals[1]), "bool", ""))
    finally:
        master.close()
    return rows
