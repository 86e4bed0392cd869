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
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=master.env(), cwd=ROOT, timeout=3600)
    # the faces print their stop lines after the result: take the result's own line
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("[") and ln.endswith("]")]
    if not lines:
        raise RuntimeError(f"the lockstep robot gave no result: {out.stderr[-2000:]}")
    sim, wall, ok = json.loads(lines[-1])
    return float(sim), float(wall), int(ok)


def _robot(master: _Master, tmp: Path, *extra: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-m", "lowerbase", "robot", "--map", "warehouse",
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
