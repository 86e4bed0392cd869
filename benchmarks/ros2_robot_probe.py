"""Run in the ROS 2 venv (by :mod:`benchmarks.bench_ros2_robot`): start ``lowerbase robot --ros2
--sim-time`` at 1 x, measure the first /odom at this rclpy subscriber (subscribed before the
start), then the robot process' CPU over ``SECONDS`` wall seconds without and with a /scan
subscriber here; prints one JSON line."""

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
        c0, w0 = cpu_seconds(robot.pid), time.monotonic()
        spin_for(node, seconds)
        without = (cpu_seconds(robot.pid) - c0) / (time.monotonic() - w0)
        scans: list[Any] = []
        node.create_subscription(LaserScan, "/scan", scans.append, qos_profile_sensor_data)
        spin_for(node, 3.0)  # matched
        n0, c0, w0 = len(scans), cpu_seconds(robot.pid), time.monotonic()
        spin_for(node, seconds)
        wall = time.monotonic() - w0
        with_scan = (cpu_seconds(robot.pid) - c0) / wall
        print(json.dumps({"start_s": start_s, "cpu_without": without, "cpu_with": with_scan,
                          "scan_rate": (len(scans) - n0) / wall,
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
