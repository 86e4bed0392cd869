"""Issue 21's table: CPU time per simulated second of each part of the lockstep robot.

``.venv/bin/python -m benchmarks.robot_sim_parts [--runs 3]`` starts a rosmaster of its own
and, ``--runs`` times, a process that becomes the lockstep robot alone (warehouse, amcl,
navigation, tasks; no client on ROS; as ``bench_robot_sim`` row (1)) and drives 3 move_base
goals between storage places (29.25 simulated s). Each part is timed by ``time.thread_time``
around its job (the scan, navigation's tick, ...) and around the lower computer and driver
core's advance; the process' user + sys time gives the total, and the rest of the main thread
is the loop itself. Prints the median of the runs per part [ms per simulated s] and the final
true pose of each run (identical from run to run). Not in ``make bench`` (needs ROS; about
10 s a run on an idle host); docs/benchmarks.md ("Issue 21, by CPU time")."""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

GOALS = 3


def one() -> dict[str, Any]:
    """One run in this process (rospy initialised here): the parts' CPU [ms per simulated s],
    the final true pose (repr of its floats)."""
    from lowerbase.robot.lockstep import LockstepOptions, LockstepRobot
    from lowerbase.robot.simrun import init_rospy
    from lowerbase.tasks.local_nav import NodeNavigation
    from lowerbase.world.maps import load_map
    from lowerbase.world.places import load_places

    rospy = init_rospy()
    r = LockstepRobot(LockstepOptions(map="warehouse"), rospy)
    r.advertise()
    r.run_periods(400)
    acc: dict[str, float] = {}

    def timed(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any) -> Any:
            t = time.thread_time()
            try:
                return fn(*args)
            finally:
                acc[name] = acc.get(name, 0.0) + time.thread_time() - t
        return run

    for job in r.jobs:
        job.work = timed(job.name, job.work)
    r._advance = timed("lower+driver", r._advance)  # type: ignore[method-assign]
    places = sorted(load_places("warehouse", load_map("warehouse")).storage.values())
    nav = NodeNavigation(r.navigation)
    s0 = r.now
    c0, t0 = os.times(), time.thread_time()
    for i in range(GOALS):
        nav.send_goal(places[(5 * i) % len(places)], now=r.now)
        r.run_periods(200)
        r.run_periods(round(120 / r.dt), r.navigation_idle)
    c1, t1 = os.times(), time.thread_time()
    sim = r.now - s0
    ms = {k: 1000.0 * v / sim for k, v in acc.items()}
    main = 1000.0 * (t1 - t0) / sim
    out = {
        "scans (lidars, amcl)": ms.get("scan", 0.0),
        "navigation (tick)": ms.get("navigation", 0.0),
        "costmaps publish": ms.get("costmaps", 0.0),
        "lower computer + driver core + driver_base's topics": ms.get("lower+driver", 0.0),
        "tasks, driver_base's periodic topics": ms.get("tasks", 0.0) + ms.get("driver", 0.0),
        "the loop itself": main - sum(ms.values()),
        "rospy's other threads": 1000.0 * ((c1.user + c1.system) - (c0.user + c0.system))
        / sim - main,
        "total": 1000.0 * ((c1.user + c1.system) - (c0.user + c0.system)) / sim,
    }
    tr = r.loop.mcu.truth
    result = {"ms": out, "sim": sim, "pose": [repr(float(tr.x)), repr(float(tr.y)),
                                              repr(float(tr.yaw))]}
    r.shutdown()
    rospy.signal_shutdown("done")
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one()))
        return 0
    from benchmarks.bench_robot_sim import ROOT, _Master

    master = _Master()
    try:
        runs = []
        for _ in range(args.runs):
            out = subprocess.run([sys.executable, "-m", "benchmarks.robot_sim_parts", "--one"],
                                 capture_output=True, text=True, env=master.env(), cwd=ROOT,
                                 timeout=1800)
            runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    finally:
        master.close()
    print(f"# load {os.getloadavg()[0]:.1f}; {runs[0]['sim']:.2f} simulated s per run")
    for key in runs[0]["ms"]:
        values = [run["ms"][key] for run in runs]
        print(f"{key:55s} {statistics.median(values):7.1f}  "
              f"({', '.join(f'{v:.1f}' for v in values)})")
    total = statistics.median(run["ms"]["total"] for run in runs)
    print(f"{'x real time by CPU (median total)':55s} {1000.0 / total:7.1f}")
    for run in runs:
        print("final true pose", *run["pose"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
