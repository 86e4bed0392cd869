"""``lowerbase robot --ros2 --sim-time`` at 1 x (warehouse): the start to the first /odom at an
rclpy subscriber in another process (subscribed before the start, on a warm environment), and
the robot process' CPU without and with a /scan subscriber (the difference is what sending
/scan over ROS 2 costs the face; the LaserScan message is built either way, for navigation in
the process). Both in the ROS 2 venv (``make ros2``); without it no rows."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from benchmarks.bench_ros2 import _ros2_env
from benchmarks.common import Row

DOMAIN = 44
PROBE = Path(__file__).resolve().with_name("ros2_robot_probe.py")


def run(quick: bool = False) -> list[Row]:
    found = _ros2_env()
    if found is None:
        return []
    python, env = found
    env["ROS_DOMAIN_ID"] = str(DOMAIN)
    seconds = 3.0 if quick else 10.0
    proc = subprocess.run([python, str(PROBE), "warehouse", str(seconds)], env=env,
                          capture_output=True, text=True, timeout=600 + 20 * seconds)
    if proc.returncode != 0:
        raise RuntimeError(f"ros2_robot_probe failed: {proc.stderr.strip()[-500:]}")
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    g = "ros2"
    extra = 100.0 * (got["cpu_with"] - got["cpu_without"])
    return [
        Row(g, "robot --ros2 --sim-time start -> first /odom", got["start_s"], "s",
            f"target <= 10 s warm; warehouse; load {got['load']:.1f}"),
        Row(g, "/scan to one rclpy subscriber: robot process CPU added", extra, "% of a core",
            f"target <= 10 %; {got['beams']} beams at {got['scan_rate']:.1f} Hz received; "
            f"process {100 * got['cpu_without']:.0f} % without, {100 * got['cpu_with']:.0f} % "
            f"with, {got['rounds']} x {seconds:g} s each, alternating, at 1 x; "
            f"load {got['load']:.1f}"),
    ]


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        print(row)
