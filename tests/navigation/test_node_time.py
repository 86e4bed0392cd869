"""The navigation node's time, ROS-free: its control loop (lowerbase.navigation.loop) on a
stand-in rospy whose time moves only when the test publishes a /clock (as under
/use_sim_time), and each scan marked at the robot's pose of its own stamp
(lowerbase.world.stamped) rather than at the newest pose."""

from __future__ import annotations

import math
import threading
from collections import deque

import pytest

from lowerbase.navigation.loop import control_loop
from lowerbase.navigation.navigator import Navigator
from lowerbase.navigation.node import NavigationSetup
from lowerbase.world.localization.poses import compose
from lowerbase.world.maps import load_map
from lowerbase.world.pacing import RosPace
from lowerbase.world.sim import WorldConfig, WorldSim
from lowerbase.world.stamped import PoseHistory, StampedSensors
from tests.driver.test_rostime import FakeRospy

Pose = tuple[float, float, float]


def test_control_loop_ticks_at_its_rate_per_second_of_ros_time_and_hands_it_that_time() -> None:
    rospy = FakeRospy()
    stop = threading.Event()
    setup = NavigationSetup(grid=load_map("empty_room"), rate_hz=20.0, costmap_rate_hz=2.0)
    ticks: list[float] = []
    published: list[float] = []
    done = threading.Condition()

    def tick(now: float) -> None:
        with done:
            ticks.append(now)
            done.notify_all()

    loop = threading.Thread(target=control_loop, daemon=True, args=(
        RosPace(rospy, stop), tick, lambda _: published.append(rospy.get_time()), setup,
        lambda: not stop.is_set()))
    rospy.clock(100.0)
    loop.start()
    # /clock in 10 ms steps; each step waits until the loop has run every tick due by then, so
    # the count depends on the clock only (3 s of it, however fast the steps come)
    t = 100.0
    for _ in range(300):
        t = round(t + 0.01, 6)
        rospy.clock(t)
        due = math.floor((t - 100.0 - 0.005) / 0.05) + 1  # a step's slack for rounding
        with done:
            assert done.wait_for(lambda d=due: len(ticks) >= d, timeout=30.0), (t, len(ticks))
    stop.set()
    rospy.clock(t + 0.01)
    loop.join(timeout=30.0)
    assert not loop.is_alive()
    in_window = [x for x in ticks if x < 102.99]
    assert len(in_window) == 60  # 20 per second of /clock
    assert ticks == sorted(ticks) and all(100.0 <= x < 104.0 for x in ticks)  # ROS time
    assert len([x for x in published if x < 102.99]) == 6  # costmaps at 2 Hz of that clock


def test_pose_history_interpolates_across_the_yaw_wrap_and_restarts_on_a_backward_clock(
        ) -> None:
    h = PoseHistory(span=1.0)
    assert h.at(0.0) is None
    h.add(1.0, (0.0, 0.0, math.pi - 0.1))
    h.add(1.1, (0.1, 0.2, -math.pi + 0.1))
    x, y, yaw = h.at(1.05) or (0, 0, 0)
    assert (x, y) == pytest.approx((0.05, 0.1)) and abs(abs(yaw) - math.pi) < 1e-9
    assert h.at(0.99) is None and h.at(1.11) is None
    for k in range(30):
        h.add(1.2 + 0.1 * k, (k, 0.0, 0.0))
    assert h.samples[0][0] >= h.samples[-1][0] - 1.0  # span kept
    h.add(0.5, (9.0, 9.0, 0.0))  # /clock restarted
    assert h.restarts == 1 and len(h.samples) == 1 and h.at(0.5) == (9.0, 9.0, 0.0)


def test_observations_wait_for_odom_to_reach_their_stamp_and_old_ones_are_counted() -> None:
    h = PoseHistory()
    m2o = (1.0, 0.0, math.pi / 2)
    sensors = StampedSensors(h, lambda t: m2o if t >= 0 else None, depth=2)
    h.add(10.0, (0.0, 0.0, 0.0))
    sensors.add("scan", 10.05, "a")
    assert sensors.ready() == []  # /odom has not reached 10.05 yet
    h.add(10.1, (0.2, 0.0, 0.0))
    [(sensor, pose, data)] = sensors.ready()
    assert (sensor, data) == ("scan", "a")
    assert pose == pytest.approx(compose(m2o, (0.1, 0.0, 0.0)))
    sensors.add("cloud", 9.0, "before the history")
    sensors.add("scan", -1.0, "no localization")
    for k in range(3):
        sensors.add("scan", 11.0 + k, k)
    assert sensors.ready() == []
    assert sensors.stats == {"waited_out": 2, "too_old": 0, "no_localization": 0,
                             "tf_waited_out": 0, "before_odom": 1}
    assert [d for _, d in sensors.pending["scan"]] == [1, 2]


def test_a_scan_from_before_the_first_odom_is_counted_quietly_an_old_one_warned_of(
        caplog: pytest.LogCaptureFixture) -> None:
    """At the robot's start the lidar's first scans come before driver_base's first /odom:
    dropped and counted, with no warning on every start; one older than a history that has
    moved on is a real loss and is warned of."""
    h = PoseHistory(span=1.0)
    sensors = StampedSensors(h, lambda t: (0.0, 0.0, 0.0))
    sensors.add("scan", 0.0, "first")
    sensors.add("scan", 0.36, "second")
    for k in range(5, 31):  # /odom from 0.5 s, 50 Hz... a second of it kept
        h.add(k / 10, (0.0, 0.0, 0.0))
    with caplog.at_level("WARNING", logger="lowerbase.world.stamped"):
        assert sensors.ready() == []
        assert caplog.records == []
        sensors.add("scan", 1.0, "older than the kept second")
        assert sensors.ready() == []
    assert sensors.stats["before_odom"] == 2 and sensors.stats["too_old"] == 1
    assert [r.getMessage() for r in caplog.records] == [
        "scan at 1.000 dropped: older than /odom's history (too_old: 1 so far)"]


def _phantoms(lag: float, stamped: bool) -> int:
    """New-obstacle cells after a turn in place among the warehouse racks, each scan cast at
    the true pose of its time and marked either at the pose of its stamp (StampedSensors over
    /odom's history) or at the newest /odom pose, ``lag`` s later (the node's old way)."""
    world = WorldSim(WorldConfig(map="warehouse", start="start"))
    nav = Navigator(world.grid)
    m2o = (6.0, 10.0, 0.0)  # odom starts here, 1.25 m from the racks; localization exact
    w = 0.6  # rad/s, in place
    history = PoseHistory()
    sensors = StampedSensors(history, lambda t: m2o)
    for k in range(int(2 * math.pi / w / 0.04)):  # 25 Hz scans, one turn
        t = 0.04 * k
        scan = world.rig.scan(world.scene, compose(m2o, (0.0, 0.0, w * t)), t)
        for j in range(3):  # /odom at 50 Hz, up to lag s after the scan
            history.add(t + lag * j / 2, (0.0, 0.0, w * (t + lag * j / 2)))
        if stamped:
            sensors.add("scan", t, scan)
            for _, pose, data in sensors.ready():
                nav.update_sensors(pose, scan=data)
        else:
            nav.update_sensors(compose(m2o, history.samples[-1][1]), scan=scan)
    return int(nav.combined.new_obstacles.sum())


def test_each_scan_is_marked_at_the_pose_of_its_stamp_so_walls_do_not_smear_into_obstacles(
        ) -> None:
    assert _phantoms(0.25, stamped=True) == 0
    # the same scans at the newest pose (0.25 s later: 0.15 rad while turning) mark cells off
    # the racks: new obstacles the planner keeps 0.7 m away from (what made move_base give up)
    assert _phantoms(0.25, stamped=False) > 50


class _PastTf:
    """A stand-in TF buffer for map -> odom that knows only the stamps it has been sent (as
    tf2: interpolated between two, no extrapolation past the newest)."""

    def __init__(self) -> None:
        self.sent: list[tuple[float, Pose]] = []

    def send(self, t: float, m2o: Pose) -> None:
        self.sent.append((t, m2o))

    def at(self, t: float) -> Pose | None:
        for (t0, p0), (t1, p1) in zip(self.sent, self.sent[1:], strict=False):
            if t0 <= t <= t1:  # poses here are (x, 0, 0): interpolated componentwise
                f = (t - t0) / (t1 - t0)
                return (p0[0] + f * (p1[0] - p0[0]), 0.0, 0.0)
        return self.sent[-1][1] if self.sent and abs(t - self.sent[-1][0]) < 1e-9 else None

    def newest(self) -> float | None:
        return self.sent[-1][0] if self.sent else None


def test_an_observation_waits_for_map_to_odom_at_its_stamp_and_is_never_marked_at_the_newest(
        ) -> None:
    """costmap_2d's tf message filter: a scan is held until TF has map -> odom at its stamp;
    marked with that one (not the newest, which amcl may have corrected since), and dropped,
    counted, when TF never reaches it within ``wait`` s of /odom."""
    h = PoseHistory()
    tf = _PastTf()
    sensors = StampedSensors(h, tf.at, tf_newest=tf.newest, wait=0.5)
    for k in range(6):
        h.add(10.0 + 0.1 * k, (0.1 * k, 0.0, 0.0))  # /odom 10.0 .. 10.5
    tf.send(10.0, (0.0, 0.0, 0.0))
    sensors.add("scan", 10.2, "a")
    assert sensors.ready() == []  # /odom has reached 10.2, TF has not: held
    tf.send(10.2, (0.0, 0.0, 0.0))  # localization at 10.2 arrives, then a correction
    tf.send(10.3, (5.0, 0.0, 0.0))
    [(_, pose, data)] = sensors.ready()
    assert data == "a" and pose == pytest.approx((0.0 + 0.2, 0.0, 0.0))  # TF at 10.2, not 10.3
    sensors.add("scan", 10.4, "b")
    sensors.add("scan", 10.5, "c")
    assert sensors.ready() == [] and len(sensors.pending["scan"]) == 2
    h.add(10.85, (0.85, 0.0, 0.0))  # still no TF after 10.3; /odom 0.45 s past "b"
    assert sensors.ready() == [] and sensors.stats["tf_waited_out"] == 0
    h.add(10.95, (0.95, 0.0, 0.0))
    assert sensors.ready() == [] and sensors.stats["tf_waited_out"] == 1  # "b": 0.55 s > 0.5
    h.add(11.0, (1.0, 0.0, 0.0))
    tf.send(10.6, (5.0, 0.0, 0.0))
    [(_, pose, data)] = sensors.ready()
    assert data == "c" and pose == pytest.approx((5.5, 0.0, 0.0))
    sensors.add("cloud", 10.1, "older than TF's cache")
    tf.sent = [s for s in tf.sent if s[0] >= 10.6]  # TF keeps nothing at 10.1 any more
    assert sensors.ready() == [] and sensors.stats["no_localization"] == 1  # never: dropped
    assert sensors.pending["cloud"] == deque()
