"""``lowerbase robot --sim-time``: what the status line shows of the simulated time.

:class:`ClockWatch` takes each /clock time with the wall time it came (``add``, fed by a rospy
subscriber from :func:`watch_clock`) and answers the newest sim time and the achieved speed
(sim seconds per wall second over the last :data:`WINDOW` wall seconds).
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

WINDOW = 5.0  #: [s] of wall time the ratio is measured over


class ClockWatch:
    def __init__(self, window: float = WINDOW,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        self.window = window
        self._monotonic = monotonic
        self._lock = threading.Lock()
        self._seen: collections.deque[tuple[float, float]] = collections.deque()

    def add(self, sim: float, wall: float | None = None) -> None:
        wall = self._monotonic() if wall is None else wall
        with self._lock:
            if self._seen and sim < self._seen[-1][1]:  # /clock restarted: measure afresh
                self._seen.clear()
            self._seen.append((wall, sim))
            while len(self._seen) > 2 and wall - self._seen[1][0] >= self.window:
                self._seen.popleft()

    @property
    def sim(self) -> float | None:
        with self._lock:
            return self._seen[-1][1] if self._seen else None

    def ratio(self) -> float | None:
        """Sim seconds per wall second over the window (None before two /clocks)."""
        with self._lock:
            if len(self._seen) < 2:
                return None
            (w0, s0), (w1, s1) = self._seen[0], self._seen[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else None

    def status(self) -> str:
        sim, ratio = self.sim, self.ratio()
        if sim is None:
            return "sim time: waiting for /clock"
        return f"sim {sim:.1f} s" + ("" if ratio is None else f" ({ratio:.2f} x real time)")


def watch_clock(watch: ClockWatch) -> Callable[[], None]:
    """Subscribe ``watch`` to /clock as a rospy node of this process (init_node without
    signal handlers: the supervisor keeps Ctrl-C); returns what ends it."""
    import importlib
    import os

    import rosgraph
    import rospy

    from lowerbase.ros1.loopback import loopback_address

    address = loopback_address(os.environ, rosgraph.get_master_uri())
    if address is not None:  # as every lowerbase node: listen on loopback with a local master
        os.environ["ROS_IP"] = address
    clock_cls = importlib.import_module("rosgraph_msgs.msg").Clock
    logging.getLogger("rospy").setLevel(logging.WARNING)  # no rospy INFO on the terminal
    rospy.init_node("lowerbase_robot", anonymous=True, disable_signals=True)

    def on_clock(msg: Any) -> None:
        watch.add(msg.clock.to_sec())

    sub = rospy.Subscriber("/clock", clock_cls, on_clock, queue_size=10)

    def close() -> None:
        sub.unregister()
        rospy.signal_shutdown("lowerbase robot stopped")

    return close
