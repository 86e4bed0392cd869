"""driver_base on ROS time: with ``/use_sim_time`` true (``lowerbase robot --sim-time``, or a
Gazebo-style /clock of your own) the node's core and its main loop follow /clock, so the
20 Hz command loop and its watchdogs run at 20 Hz of *simulated* time, whatever its speed; with
``/use_sim_time`` false nothing changes (a :class:`~lowerbase.clock.RealClock`).

:class:`RosClock` is a :class:`~lowerbase.clock.Clock` reading ``rospy.get_time()``;
:class:`Pacer` keeps the main loop's period on any clock (sleeping on the stop event for a
real clock, waiting for /clock to pass the deadline for a RosClock); :func:`wait_for_clock`
holds the start until the first /clock arrives (before it ROS time is 0).
"""

from __future__ import annotations

import threading
import time
from typing import Any

from lowerbase.clock import Clock

#: [s] how long a wait for /clock sleeps at most before it looks at the stop flags again
POLL = 0.1
#: [s] of clock time after which a late loop stops catching up, or a clock that jumped back is
#: followed at once
SLACK = 1.0
#: [s, wall] over which :meth:`RosClock.ago` measures /clock's speed; the fastest it believes
RATE_WINDOW = 1.0
MAX_RATE = 100.0


class RosClock:
    """ROS time (``rospy.get_time()``): /clock's under ``/use_sim_time``, else the wall's."""

    is_simulated = False

    def __init__(self, rospy: Any, stop: threading.Event | None = None,
                 wall: Any = time.monotonic) -> None:
        self.rospy = rospy
        self.stop = stop or threading.Event()
        self._wall = wall
        self._mark: tuple[float, float] | None = None  # (wall, ROS time) of the rate's window
        self.rate = 1.0  #: ROS seconds per wall second (/clock's speed), measured

    def now(self) -> float:
        return float(self.rospy.get_time())

    def ago(self, wall_seconds: float) -> float:
        """The ROS time ``wall_seconds`` of wall time ago, at /clock's measured speed (a frame
        that waited in the socket, stamped when it arrived)."""
        now, wall = self.now(), self._wall()
        if self._mark is None or now < self._mark[1]:
            self._mark = (wall, now)
        elif wall - self._mark[0] >= RATE_WINDOW:
            self.rate = min(max((now - self._mark[1]) / (wall - self._mark[0]), 0.0), MAX_RATE)
            self._mark = (wall, now)
        return now - wall_seconds * self.rate

    def _stopped(self) -> bool:
        return self.stop.is_set() or bool(self.rospy.is_shutdown())

    def sleep_until(self, deadline: float) -> None:
        """Until ROS time reaches ``deadline``, the stop event is set or rospy shuts down
        (woken by every /clock message: rospy's time condition)."""
        cond = self.rospy.rostime.get_rostime_cond()
        with cond:
            while self.now() < deadline and not self._stopped():
                cond.wait(POLL)


def uses_sim_time(rospy: Any) -> bool:
    """True when this node's ROS time is /clock's (``/use_sim_time`` true at init_node)."""
    return not rospy.rostime.is_wallclock()


def wait_for_clock(rospy: Any, stop: threading.Event, announce: Any = print) -> bool:
    """Under sim time: block until /clock has given a time (> 0); False if stopped first."""
    if not uses_sim_time(rospy) or rospy.get_time() > 0:
        return True
    announce("lowerbase driver: /use_sim_time is true: waiting for /clock (lowerbase world "
             "--publish-clock, or your simulator)")
    clock = RosClock(rospy, stop)
    clock.sleep_until(1e-9)
    return rospy.get_time() > 0


class Pacer:
    """Calls to :meth:`wait` return once per ``period`` of ``clock`` time (no burst after a
    stall longer than :data:`SLACK`; a clock that jumped back is followed)."""

    def __init__(self, clock: Clock, period: float, stop: threading.Event) -> None:
        self.clock = clock
        self.period = period
        self.stop = stop
        self.deadline = clock.now()

    def wait(self) -> None:
        self.deadline += self.period
        now = self.clock.now()
        if now - self.deadline > SLACK or self.deadline - now > SLACK + self.period:
            self.deadline = now  # suspended, overloaded, or time moved backwards
        if isinstance(self.clock, RosClock):
            self.clock.sleep_until(self.deadline)
        else:
            self.stop.wait(max(self.deadline - now, 0.0))
