"""How the world node's sensor loops keep their rates: on the wall clock, or on ROS time.

Under ``/use_sim_time`` (``lowerbase robot --sim-time``: the emulator runs K x real time and
the world publishes /clock from its ground truth) a sensor's rate is per simulated second, so
its loop must run on ROS time: :class:`RosPace` reads ``rospy.get_time()`` and sleeps on
rospy's time condition, which rospy notifies on every /clock it receives (as ``rospy.sleep``
does), so the loop wakes on /clock. Otherwise :class:`WallPace` (the monotonic clock).

:func:`paced_loop` is the loop itself, the same on either: ``work()`` every ``1 / rate_hz``
[s of that time]; a late tick is caught up (``catch_up``: up to 1 s late) or, once a whole
period late, dropped and counted (each period of the schedule is either run or counted);
time that went backwards (a /clock restarted by someone else) starts the schedule
again from now.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

#: [s] how long a wait on ROS time sleeps before it looks at the stop flag again (wall)
_POLL = 0.1


class Pace(Protocol):
    def now(self) -> float:
        """The current time [s] on this pace's clock."""
        ...

    def wait_until(self, due: float) -> None:
        """Return once ``now() >= due`` or the loop should stop."""
        ...


class WallPace:
    """The monotonic wall clock; ``stop`` ends a wait at once."""

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop

    def now(self) -> float:
        return time.monotonic()

    def wait_until(self, due: float) -> None:
        self.stop.wait(max(due - time.monotonic(), 0.0))


class RosPace:
    """ROS time (``rospy.get_time()``: sim time under /use_sim_time); a wait wakes on each
    /clock rospy receives and ends on ``stop`` or rospy's shutdown."""

    def __init__(self, rospy: Any, stop: threading.Event) -> None:
        self.rospy = rospy
        self.stop = stop

    def now(self) -> float:
        return float(self.rospy.get_time())

    def wait_until(self, due: float) -> None:
        rospy = self.rospy
        cond = rospy.rostime.get_rostime_cond()
        with cond:
            while (not self.stop.is_set() and not rospy.is_shutdown()
                   and float(rospy.get_time()) < due):
                cond.wait(_POLL)


def pace_for(rospy: Any, stop: threading.Event) -> Pace:
    """:class:`RosPace` when ``/use_sim_time`` is true on the master, else :class:`WallPace`."""
    sim = bool(rospy.get_param("/use_sim_time", False))
    return RosPace(rospy, stop) if sim else WallPace(stop)


def paced_loop(pace: Pace, work: Callable[[], None], rate_hz: float, catch_up: bool,
               running: Callable[[], bool], dropped: Callable[[int], None] | None = None
               ) -> None:
    """``work()`` at ``rate_hz`` on ``pace``'s clock while ``running()`` (see the module)."""
    period = 1.0 / rate_hz
    due = pace.now()
    while running():
        pace.wait_until(due)
        if not running():
            break
        work()
        due += period
        now = pace.now()
        if due - now > 1.0 + period:  # the clock went backwards: start again from now
            due = now
            continue
        late = now - due
        if catch_up:
            if late > 1.0:
                due = now
        elif late > period:  # whole periods missed: dropped, on the schedule's phase
            missed = int(late / period + 1e-6)
            if dropped is not None:
                dropped(missed)
            due += missed * period


#: [s] how often a sensor that cannot keep its rate says what rate it achieves
RATE_REPORT_EVERY = 30.0


class RateWatch:
    """The rate a dropping loop achieves (``paced_loop(..., catch_up=False)``: the camera):
    :meth:`done` per work done, :meth:`dropped` per skipped tick; :meth:`report` gives, at most
    every ``every`` s of the loop's time and only when ticks were dropped since the last
    report, one line with the achieved rate (None otherwise)."""

    def __init__(self, name: str, rate_hz: float, every: float = RATE_REPORT_EVERY,
                 what: str = "frame") -> None:
        self.name, self.rate_hz, self.every, self.what = name, rate_hz, every, what
        self.total_done = self.total_dropped = 0
        self._since: float | None = None
        self._done = self._dropped = 0

    def done(self, now: float) -> None:
        if self._since is None:
            self._since = now
        self._done += 1
        self.total_done += 1

    def done_and_warn(self, now: float, log: logging.Logger) -> None:
        """:meth:`done`, then the :meth:`report` line, when one is due, as a warning on
        ``log`` (the dropping loop's own logger)."""
        self.done(now)
        line = self.report(now)
        if line is not None:
            log.warning("%s", line)

    def dropped(self, n: int) -> None:
        self._dropped += n
        self.total_dropped += n

    def report(self, now: float) -> str | None:
        if self._since is None or now - self._since < self.every:
            return None
        span, done, dropped = now - self._since, self._done, self._dropped
        self._since, self._done, self._dropped = now, 0, 0
        if not dropped:
            return None
        return (f"{self.name}: {done / span:.1f} Hz of {self.rate_hz:g} Hz over the last "
                f"{span:.0f} s ({dropped} {self.what}s dropped: a {self.what} takes longer than "
                f"a period on this host); a lower rate keeps its period")
