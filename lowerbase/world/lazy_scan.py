"""A scan cast only when someone reads it: :class:`LazyScan`.

The lockstep robot (``lowerbase robot --sim-time``) makes /scan at the lidars' rate (25 Hz),
but when no node outside the process takes /scan, its only readers are navigation's costmap
(the newest scan at each update, 5 Hz) and the localizer (a scan after ``update_min_d`` of
travel): most scans are never read. The world then draws each scan's random numbers at its
tick (the lidars' generators are stateful, so every scan is what it would have been had all
been cast) and keeps what the cast needs; the ray cast runs on the first read, once. A scan
read is bit for bit the scan cast at its tick (tests/world/test_lazy_scan.py).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from lowerbase.world.lidar import LaserScan


class LazyScan:
    """A :class:`~lowerbase.world.lidar.LaserScan` made by ``make()`` when first read (once);
    ``frame_id`` and ``stamp`` [s] are at hand without it."""

    __slots__ = ("_make", "_scan", "frame_id", "stamp")

    def __init__(self, frame_id: str, stamp: float, make: Callable[[], LaserScan]) -> None:
        self.frame_id = frame_id
        self.stamp = stamp
        self._make: Callable[[], LaserScan] | None = make
        self._scan: LaserScan | None = None

    @property
    def cast(self) -> bool:
        """Whether the scan has been made."""
        return self._scan is not None

    def scan(self) -> LaserScan:
        """The scan itself (made now if it was not yet)."""
        if self._scan is None:
            assert self._make is not None
            self._scan, self._make = self._make(), None
        return self._scan

    # what a localizer reads (lowerbase.world.localization.likelihood.ScanLike)
    @property
    def ranges(self) -> np.ndarray:
        return self.scan().ranges

    @property
    def angle_min(self) -> float:
        return self.scan().angle_min

    @property
    def angle_increment(self) -> float:
        return self.scan().angle_increment

    @property
    def range_min(self) -> float:
        return self.scan().range_min

    @property
    def range_max(self) -> float:
        return self.scan().range_max


def resolve(scan: LaserScan | LazyScan) -> LaserScan:
    """The scan itself, whether it came cast or lazy."""
    return scan.scan() if isinstance(scan, LazyScan) else scan
