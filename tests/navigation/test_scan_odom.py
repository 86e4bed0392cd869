"""The world's localization pairs each scan with /odom at the scan's stamp (ROS-free, on a
simulated timeline): with /odom delivered late, as under ``--sim-time --speed 2``, map -> odom
stays right, so the navigation node's marking pose (map -> odom and /odom at the stamp) is
the true pose; pairing with the newest /odom received (the world node's old rule) is off by
the turn made in the delay."""

from __future__ import annotations

import math

from lowerbase.world.localization.poses import compose, inverse
from lowerbase.world.scan_odom import ScanOdom
from lowerbase.world.stamped import PoseHistory

Pose = tuple[float, float, float]
LAG = 0.6  #: [s] /odom arrives this long after its stamp
ODOM_HZ, SCAN_HZ = 50, 25


def truth(t: float) -> Pose:
    """Turning at 0.5 rad/s on a 1 m circle: the true map pose (and perfect odometry)."""
    return (math.sin(0.5 * t), 1.0 - math.cos(0.5 * t), 0.5 * t)


def yaw_error(a: Pose, b: Pose) -> float:
    return abs(math.remainder(a[2] - b[2], math.tau))


def run(pair_at_stamp: bool, lag: float = LAG) -> list[tuple[float, Pose]]:
    """(stamp, marking pose) of each scan over 6 s; map -> odom from the ground truth (the
    localizer's ideal) with the odometry each rule pairs the scan with."""
    world = ScanOdom()
    received: Pose | None = None
    m2o_by_stamp: list[tuple[float, Pose]] = []
    nav_odom = PoseHistory()
    odom_stamps = [i / ODOM_HZ for i in range(6 * ODOM_HZ)]
    for k in range(1, 6 * SCAN_HZ):
        now = k / SCAN_HZ
        for s in [s for s in odom_stamps if s + lag <= now]:  # /odom delivered late
            world.add_odom(s, truth(s))
            nav_odom.add(s, truth(s))
            received = truth(s)
            odom_stamps.remove(s)
        if received is None:
            continue
        if pair_at_stamp:
            world.add_scan(now, "scan")
            for at, odom, _ in world.ready():
                m2o_by_stamp.append((at, compose(truth(at), inverse(odom))))
        else:
            m2o_by_stamp.append((now, compose(truth(now), inverse(received))))
    out = []
    for at, m2o in m2o_by_stamp:
        odom = nav_odom.at(at)
        if odom is not None:
            out.append((at, compose(m2o, odom)))
    return out


def test_scans_paired_with_odom_at_their_stamp_mark_at_the_true_pose() -> None:
    marks = run(pair_at_stamp=True)
    assert len(marks) > 100
    for at, pose in marks:
        assert math.dist(pose[:2], truth(at)[:2]) < 1e-6 and yaw_error(pose, truth(at)) < 1e-6


def test_odom_2_5_s_late_still_pairs_every_scan_as_amcls_100_scan_queue_does() -> None:
    """At --sim-time --speed 2 on a loaded 2-core host /odom reached the world up to 2.5 s of
    /clock late (docs/robot.md); a 1 s queue (25 scans) dropped those scans unlocalized."""
    lag = 2.5
    marks = run(pair_at_stamp=True, lag=lag)
    last = (6 * SCAN_HZ - 1) / SCAN_HZ
    # every scan from the first /odom's arrival on that /odom has reached by the end
    assert len(marks) == sum(1 for k in range(1, 6 * SCAN_HZ)
                             if lag - 1e-9 <= k / SCAN_HZ <= last - lag + 1e-9) > 20
    assert all(math.dist(pose[:2], truth(at)[:2]) < 1e-6 for at, pose in marks)


def test_pairing_with_the_newest_odom_received_is_off_by_the_delay() -> None:
    worst = max(yaw_error(pose, truth(at)) for at, pose in run(pair_at_stamp=False))
    assert worst > 0.25  # 0.5 rad/s x 0.6 s


def test_a_scan_waits_for_odom_then_comes_out_once() -> None:
    pairing = ScanOdom()
    pairing.add_odom(0.0, (0.0, 0.0, 0.0))
    pairing.add_scan(0.1, "a")
    assert pairing.ready() == []
    pairing.add_odom(0.2, (0.2, 0.0, 0.0))
    [(at, odom, scan)] = pairing.ready()
    assert (at, scan) == (0.1, "a") and math.isclose(odom[0], 0.1)
    assert pairing.ready() == []


def test_a_repeated_stamp_is_dropped_counted_and_a_restarted_clock_taken() -> None:
    pairing = ScanOdom()
    assert pairing.fresh(10.0)
    assert not pairing.fresh(10.0)  # a catch-up within one /clock step
    assert not pairing.fresh(9.96)
    assert pairing.counts["repeated"] == 2
    assert pairing.fresh(10.04)
    assert pairing.fresh(0.5)  # /clock restarted
