"""amcl's pairing of each scan with /odom *at the scan's stamp* (its message filter on TF),
ROS-free: :class:`ScanOdom` holds each scan until /odom has reached its stamp, then hands it
out once with the odometry pose interpolated there, and the world stamps the map -> odom it
computes from the pair with that same stamp.

Pairing a scan with the newest /odom received instead (what the world node did) puts the
odometry of another instant into map -> odom: under ``--sim-time --speed 2`` /odom arrived up
to ~0.8 s of /clock off the scan, so while turning at 0.4 rad/s the transform was up to 0.3
rad wrong at the scan's stamp, and the navigation node, which marks each scan at map -> odom
and /odom of its stamp (``lowerbase.world.stamped``), smeared the racks across the aisle.

A scan with a stamp not after the last one handed out (the sensor loop caught up twice within
one coarse /clock step) is dropped, counted: tf2 would drop its transform as TF_REPEATED_DATA.
"""

from __future__ import annotations

from typing import Any

from lowerbase.world.stamped import PoseHistory, StampedSensors

Pose = tuple[float, float, float]
_ORIGIN: Pose = (0.0, 0.0, 0.0)


class ScanOdom:
    """Scans waiting for /odom (at most ``depth``, older ones dropped: amcl's message filter
    queue of 100 scans, 4 s at 25 Hz; /odom came up to 2.5 s of /clock late at K=2 on a
    loaded host, and a 25-scan queue lost those scans unlocalized)."""

    def __init__(self, span: float = 5.0, depth: int = 100) -> None:
        self.odom = PoseHistory(span)
        self._waiting = StampedSensors(self.odom, lambda stamp: _ORIGIN, depth)
        self.last_stamp: float | None = None  #: the stamp of the last scan handed out
        self.stats = {"repeated": 0}

    def add_odom(self, stamp: float, pose: Pose) -> None:
        self.odom.add(stamp, pose)

    def fresh(self, stamp: float) -> bool:
        """False (counted) for a stamp not after the last scan's: the same instant again; a
        stamp more than 1 s back is a restarted /clock and taken."""
        last = self.last_stamp
        if last is not None and last - 1.0 < stamp <= last:
            self.stats["repeated"] += 1
            return False
        self.last_stamp = stamp
        return True

    def add_scan(self, stamp: float, scan: Any) -> None:
        self._waiting.add("scan", stamp, (stamp, scan))

    def ready(self) -> list[tuple[float, Pose, Any]]:
        """(stamp, /odom pose at the stamp, scan) of each scan /odom has reached, oldest first;
        one from before /odom's history is dropped (counted in :attr:`counts`)."""
        return [(data[0], odom, data[1]) for _, odom, data in self._waiting.ready()]

    @property
    def counts(self) -> dict[str, int]:
        s = self._waiting.stats
        return {"repeated": self.stats["repeated"], "waited_out": s["waited_out"],
                "too_old": s["too_old"]}
