"""Run in the ROS 2 venv (by :mod:`benchmarks.bench_ros2_robot`): start ``lowerbase robot --ros2
--sim-time`` at 1 x, measure the first /odom at this rclpy subscriber (subscribed before the
start), then the robot process' CPU over ``ROUNDS`` x ``SECONDS`` wall seconds without and with a
/scan subscriber here, alternating; prints one JSON line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from typing import Any

import rclpy
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

from lowerbase.ros2.wire import qos_for

TIMEOUT = 300.0
ROUNDS = 4  #: without and with a /scan subscriber, alternating


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def spin_for(node: Node, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)


def main() -> None:
    mapname, seconds = sys.argv[1], float(sys.argv[2])
    rclpy.init()
    node = rclpy.create_node("lowerbase_bench_robot")
    first: list[float] = []
    node.create_subscription(Odometry, "/odom", lambda _m: first.append(time.monotonic()),
                             qos_for("/odom", 10))
    t0 = time.monotonic()
    robot = subprocess.Popen([sys.executable, "-m", "lowerbase", "robot", "--ros2",
                              "--sim-time", "--map", mapname],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        while not first:
            if time.monotonic() - t0 > TIMEOUT:
                sys.exit(f"no /odom within {TIMEOUT:.0f} s")
            rclpy.spin_once(node, timeout_sec=0.02)
        start_s = first[0] - t0
        spin_for(node, 5.0)  # settled
        scans: list[Any] = []
        cpu = {"without": 0.0, "with": 0.0}
        walls = {"without": 0.0, "with": 0.0}
        got = 0
        for _ in range(ROUNDS):  # alternating: the robot's own load drifts
            for case in ("without", "with"):
                sub = None
                if case == "with":
                    sub = node.create_subscription(LaserScan, "/scan", scans.append,
                                                   qos_profile_sensor_data)
                    spin_for(node, 2.0)  # matched
                n0, c0, w0 = len(scans), cpu_seconds(robot.pid), time.monotonic()
                spin_for(node, seconds)
                cpu[case] += cpu_seconds(robot.pid) - c0
                walls[case] += time.monotonic() - w0
                got += len(scans) - n0
                if sub is not None:
                    node.destroy_subscription(sub)
                    spin_for(node, 2.0)  # unmatched
        without, with_scan = (cpu[c] / walls[c] for c in ("without", "with"))
        wall = walls["with"]
        print(json.dumps({"start_s": start_s, "cpu_without": without, "cpu_with": with_scan,
                          "scan_rate": got / wall, "rounds": ROUNDS,
                          "beams": len(scans[-1].ranges) if scans else 0,
                          "load": os.getloadavg()[0]}), flush=True)
    finally:
        robot.send_signal(2)
        try:
            robot.wait(timeout=60)
        except subprocess.TimeoutExpired:
            robot.kill()
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
