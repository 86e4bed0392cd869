"""Each observation at the robot's pose of its own time stamp, as costmap_2d's tf message
filters do: :class:`PoseHistory` keeps /odom's stamped poses; :class:`StampedSensors` holds each
/scan and each camera cloud until /odom has reached its stamp, then hands it out once with the
map pose of that instant (map -> odom at the stamp composed with /odom interpolated there).

Marking a scan at the *latest* pose instead (what the navigation node did) puts it where the
robot is when the control loop gets to it, not where the lidar was: while turning at 0.5 rad/s a
scan 0.2 s old lands 0.1 rad off, 25 cm at 2.5 m, and walls smeared that far from the map's own
walls count as new obstacles (``combined``: 0.15 m), which made move_base replan until it gave
up. A camera cloud re-marked with every newer scan was smeared the same way.

Map -> odom is taken at the stamp too, never the newest: TF has it there only once the world's
localization has processed that instant (the same scan, with /odom at its stamp), so an
observation whose /odom is known waits for it, as costmap_2d's tf2 message filter holds a
scan until its transform is available; it is dropped (counted, logged) when TF never will have
it (older than TF's cache) or has not got it once /odom is ``wait`` s past its stamp.

ROS-free: the times are any clock's seconds (the stamps' own; ROS time under /use_sim_time).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from typing import Any

from lowerbase.errors import worth_logging
from lowerbase.world.localization.poses import compose

log = logging.getLogger(__name__)

Pose = tuple[float, float, float]


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


class PoseHistory:
    """Stamped poses, oldest first, ``span`` s of them; :meth:`at` interpolates."""

    def __init__(self, span: float = 5.0) -> None:
        self.span = span
        self.samples: deque[tuple[float, Pose]] = deque()
        self.restarts = 0  #: times the stamps went backwards (a restarted /clock): history reset
        #: the first stamp since the start (or the last restart); None before any
        self.since: float | None = None

    @property
    def newest(self) -> float | None:
        return self.samples[-1][0] if self.samples else None

    def add(self, t: float, pose: Pose) -> None:
        s = self.samples
        if s and t < s[-1][0]:
            s.clear()
            self.restarts += 1
        if not s:
            self.since = t
        s.append((t, pose))
        while s[-1][0] - s[0][0] > self.span:
            s.popleft()

    def at(self, t: float) -> Pose | None:
        """The pose at ``t``, interpolated between the samples around it; None outside them."""
        s = self.samples
        if not s or t < s[0][0] - 1e-6 or t > s[-1][0] + 1e-6:
            return None
        hi = len(s) - 1
        while hi > 0 and s[hi - 1][0] >= t:
            hi -= 1  # newest first: the usual stamp is recent
        t1, p1 = s[hi]
        if hi == 0 or t1 <= t:
            return p1
        t0, p0 = s[hi - 1]
        f = (t - t0) / (t1 - t0)
        return (p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]),
                _wrap(p0[2] + f * _wrap(p1[2] - p0[2])))


class StampedSensors:
    """Observations waiting for /odom and map -> odom to reach their stamp (at most ``depth``
    per sensor, 1 s of 25 Hz scans: under /use_sim_time driver_base stamps /odom on a /clock
    that may lag the world's; an older one is dropped, counted in ``stats``).

    ``map_to_odom(stamp)`` is TF's map -> odom at the stamp (None: not known there);
    ``tf_newest()`` the newest stamp TF has it at (None: none yet). Without ``tf_newest``
    map -> odom is taken to be known at every stamp it will ever be (no waiting)."""

    def __init__(self, odom: PoseHistory, map_to_odom: Callable[[float], Pose | None],
                 depth: int = 25, tf_newest: Callable[[], float | None] | None = None,
                 wait: float = 1.0) -> None:
        self.odom = odom
        self.map_to_odom = map_to_odom
        self.tf_newest = tf_newest
        self.depth = depth
        self.wait = wait  #: [s of /odom past a stamp] the longest wait for TF to reach it
        self.pending: dict[str, deque[tuple[float, Any]]] = {}
        self.stats = {"waited_out": 0, "too_old": 0, "no_localization": 0, "tf_waited_out": 0,
                      "before_odom": 0}

    def add(self, sensor: str, stamp: float, data: Any) -> None:
        q = self.pending.setdefault(sensor, deque())
        q.append((stamp, data))
        while len(q) > self.depth:
            q.popleft()
            self.stats["waited_out"] += 1

    def ready(self) -> list[tuple[str, Pose, Any]]:
        """(sensor, map pose at its stamp, data) of every observation /odom and TF have caught
        up with, oldest first per sensor; one older than /odom's history, or than TF's, or
        that TF has not reached ``wait`` s of /odom after it, is dropped (counted, warned of);
        one from before the first /odom (the robot's start) is dropped and counted only."""
        out: list[tuple[str, Pose, Any]] = []
        newest = self.odom.newest
        for sensor, q in self.pending.items():
            while q and newest is not None and q[0][0] <= newest + 1e-6:
                stamp, data = q[0]
                odom = self.odom.at(stamp)
                if odom is None:
                    q.popleft()
                    since = self.odom.since
                    if since is not None and stamp < since:  # a start: counted, not warned of
                        self.stats["before_odom"] += 1
                        log.debug("%s at %.3f dropped: before the first /odom", sensor, stamp)
                    else:
                        self._drop("too_old", sensor, stamp, "older than /odom's history")
                    continue
                m2o = self.map_to_odom(stamp)
                if m2o is not None:
                    q.popleft()
                    out.append((sensor, compose(m2o, odom), data))
                    continue
                tf = self.tf_newest() if self.tf_newest is not None else None
                if self.tf_newest is None or (tf is not None and tf >= stamp - 1e-9):
                    q.popleft()  # TF is past it and has nothing there: it never will
                    self._drop("no_localization", sensor, stamp, "no map -> odom there")
                elif newest - stamp > self.wait:
                    q.popleft()
                    self._drop("tf_waited_out", sensor, stamp,
                               f"no map -> odom there {newest - stamp:.2f} s of /odom later")
                else:
                    break  # held until TF reaches its stamp
        return out

    def _drop(self, key: str, sensor: str, stamp: float, why: str) -> None:
        n = self.stats[key] = self.stats[key] + 1
        if worth_logging(n):
            log.warning("%s at %.3f dropped: %s (%s: %d so far)", sensor, stamp, why, key, n)
