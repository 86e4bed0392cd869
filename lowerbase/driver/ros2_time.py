"""ROS 2's /clock for a face's core and loop: :class:`Ros2Clock`, the rclpy twin of
:class:`lowerbase.driver.rostime.RosClock` (``use_sim_time`` true).

It takes /clock itself (rosgraph_msgs/Clock, best effort as rclpy's TimeSource does), so that
:meth:`Ros2Clock.sleep_until` is woken by each /clock message and :meth:`Ros2Clock.now` is
the time that woke it. :class:`lowerbase.driver.rostime.Pacer` paces the loop on it as on
ROS 1's.
"""

from __future__ import annotations

import threading
from typing import Any

from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg

from lowerbase.driver.rostime import POLL, RosClock
from lowerbase.ros2.wire import clock_qos


class Ros2Clock(RosClock):
    """/clock's time [s]; 0 until the first /clock. ``shim``: the face's
    :class:`~lowerbase.ros2.wire.RclpyShim` (its shutdown ends every wait)."""

    is_simulated = False

    def __init__(self, node: Node, shim: Any, stop: threading.Event | None = None) -> None:
        super().__init__(shim, stop)
        self._cond = threading.Condition()
        self._time = 0.0
        self._sub = node.create_subscription(ClockMsg, "/clock", self._on_clock, clock_qos())

    def _on_clock(self, msg: ClockMsg) -> None:
        with self._cond:
            self._time = msg.clock.sec + msg.clock.nanosec * 1e-9
            self._cond.notify_all()

    def now(self) -> float:
        return self._time

    def sleep_until(self, deadline: float) -> None:
        """Until /clock reaches ``deadline``, the stop event is set or the node shuts down."""
        with self._cond:
            while self._time < deadline and not self._stopped():
                self._cond.wait(POLL)

    def wait_for_first(self) -> bool:
        """Block until /clock has given a time (> 0); False if stopped first."""
        self.sleep_until(1e-9)
        return self._time > 0
