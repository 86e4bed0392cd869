"""What the ROS 2 probes (ros2_*_probe.py) share. They run as scripts
in the ROS 2 venv, where ``tests`` is not importable: they import this as ``probe_common``,
found through their own directory (sys.path[0] for a script)."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import Any

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node

from lowerbase.ros2.wire import qos_for


def spin_until(node: Node, done: Callable[[], bool], what: str, timeout: float) -> None:
    """Spin ``node`` until ``done()``; exit in one line if ``timeout`` [s] passes first."""
    deadline = time.monotonic() + timeout
    while not done():
        if time.monotonic() > deadline:
            sys.exit(f"probe: {what} not seen within {timeout:.0f} s")
        rclpy.spin_once(node, timeout_sec=0.1)


def call(node: Node, cls: Any, name: str, request: Any, timeout: float) -> Any:
    """Service ``name`` (type ``cls``) called with ``request`` once it is there: its response;
    each wait fails in one line after ``timeout`` [s]."""
    client = node.create_client(cls, name)
    spin_until(node, client.service_is_ready, f"{name} ready", timeout)
    future = client.call_async(request)
    spin_until(node, future.done, f"{name}'s answer", timeout)
    return future.result()


def sec(stamp: Any) -> float:
    return float(stamp.sec) + stamp.nanosec * 1e-9


def drive(node: Node, timeout: float) -> dict[str, Any]:
    """A Twist on /base_cmd_vel from this process (20 Hz, as a teleop) until /odom moved
    0.2 m, then zeros: how far /odom moved and its last speed."""
    got: list[Odometry] = []
    node.create_subscription(Odometry, "/odom", got.append, qos_for("/odom", 50))
    spin_until(node, lambda: bool(got), "/odom", timeout)
    x0, y0 = got[-1].pose.pose.position.x, got[-1].pose.pose.position.y
    pub = node.create_publisher(Twist, "/base_cmd_vel", qos_for("/base_cmd_vel"))
    cmd = Twist()
    cmd.linear.x = 0.3
    deadline = time.monotonic() + timeout
    next_cmd = 0.0

    def moved() -> float:
        p = got[-1].pose.pose.position
        return math.hypot(p.x - x0, p.y - y0)

    while moved() < 0.2:
        if time.monotonic() > deadline:
            sys.exit(f"probe: /odom moved {moved():.3f} m, not 0.2, within {timeout:.0f} s "
                     "of commanding")
        if time.monotonic() >= next_cmd:
            pub.publish(cmd)
            next_cmd = time.monotonic() + 0.05
        rclpy.spin_once(node, timeout_sec=0.02)
    speed = got[-1].twist.twist.linear.x
    for _ in range(5):
        pub.publish(Twist())
        rclpy.spin_once(node, timeout_sec=0.02)
    return {"moved": moved(), "speed": speed}
