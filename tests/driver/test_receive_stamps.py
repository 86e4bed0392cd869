"""A driver that falls behind its bus (a busy host: the reader starved, the node's lock held by
the tick) gets a backlog of frames at once. The core judges wheel-sample gaps on when the
frames arrived, not on when it got to them; and handled as a burst at one instant, the backlog
that reads as a gap and a Counter discontinuity is integrated as the longer interval it is (it
re-baselined and lost the robot's motion: 34 re-baselines in real time in `lowerbase robot` on a
loaded host, 152 at --speed 2, and amcl lost the robot). The bus's receive stamps (the
kernel's, on udp_multicast and SocketCAN) reach the core through ``BusLink.last_age``."""

from __future__ import annotations

import logging
import math
from collections import Counter
from typing import Any

import can
import pytest

from lowerbase.clock import SimClock
from lowerbase.driver.core import LinkState
from lowerbase.driver.links import (
    LATE_HANDLING,
    MAX_RECEIVE_AGE,
    BusLink,
    HandlingLag,
    receive_age,
)
from lowerbase.driver.rostime import RosClock
from lowerbase.simloop.loop import SimLoop

STALL = 0.3  #: [s] the reader does not run; then it handles everything that queued up
EVERY = 1.0  #: [s] between stalls


class StallingLoop(SimLoop):
    """SimLoop whose driver handles the lower computer's frames late, in bursts: nothing for
    ``stall`` s every ``EVERY`` s, then the backlog at once, stamped as ``stamped`` says; with
    ``heard``, the reader tells the core how far it has listened, as the node does."""

    def __init__(self, stamped: bool, stall: float = STALL, heard: bool = False) -> None:
        super().__init__(bms=None)
        self.stamped = stamped
        self.stall = stall
        self.heard = heard
        self.backlog: list[tuple[float, int, bytes]] = []

    def queue_frames(self) -> None:
        """One period of the lower computer; its frames join the reader's backlog."""
        for frame_id, data in self._to_mcu:
            self.mcu.receive(frame_id, data)
        self._to_mcu.clear()
        self.mcu.step()
        self.backlog += self._to_driver
        self._to_driver = []

    def step(self) -> None:
        self.queue_frames()
        every = max(EVERY, 2 * self.stall)
        if self.clock.now() % every >= self.stall:  # the reader runs: the backlog, in order
            for stamp, frame_id, data in self.backlog:
                if self.heard:
                    self.driver.heard_until = stamp
                self.driver.on_frame(frame_id, data, stamp if self.stamped else None)
            self.backlog.clear()
            if self.heard:  # and found the socket empty
                self.driver.heard_until = self.clock.now()
        self.driver.tick()
        self.clock.advance(self.mcu.dt)


SPEEDS: list[float] = []  #: /odom_raw's linear speeds [m/s] of the last drive()


def drive(stamped: bool, stall: float = STALL, heard: bool = False
          ) -> tuple[float, float, int, int]:
    """(distance on /odom_raw, true distance, re-baselines, links lost) over 6 s at 0.5 m/s;
    /odom_raw's speed after every period in SPEEDS."""
    loop = StallingLoop(stamped, stall, heard)
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.READY, timeout=5.0)
    odo = loop.driver.odometry
    assert odo is not None
    x0, true0 = odo.x, loop.mcu.truth.x
    before = loop.driver.stats["odometry_rebaselined"]
    lost = loop.driver.stats["link_lost"]
    SPEEDS.clear()
    loop.drive(0.5, 0.0, 6.0, on_step=lambda lp: SPEEDS.append(odo.linear))
    loop.run(1.0)  # the last backlog handled
    return (odo.x - x0, loop.mcu.truth.x - true0,
            loop.driver.stats["odometry_rebaselined"] - before,
            loop.driver.stats["link_lost"] - lost)


def test_a_backlog_handled_at_once_loses_no_motion_and_no_speed_is_made_up() -> None:
    """Stamped on handling (no receive stamps: a bus without them), each stall's backlog
    reads as a gap and a Counter discontinuity. The counts are absolute: the gap is only a
    longer interval, its samples stamped on the Counter's cycles (issue 22 items 1 and 2:
    /odom lost 0.64 m and 9.2 deg on a 19.2 m loop under load, /odom_raw said 39 m/s)."""
    raw, true, rebaselined, _ = drive(stamped=False)
    assert rebaselined == 0
    assert raw == pytest.approx(true, abs=0.02)
    # no speed from a burst's handling times (it said 10.7 m/s here before the samples were
    # stamped on the Counter's cycles across a stall): what is left is the unstamped bus's
    # arrival jitter within half a cycle (one sample handled 5 ms late: 0.4, then 0.67 m/s);
    # with the kernel's receive stamps (test below) every speed is 0.500
    assert max(abs(v) for v in SPEEDS) <= 0.5 * 1.4


def test_a_backlog_stamped_when_received_keeps_every_wheel_count() -> None:
    raw, true, rebaselined, _ = drive(stamped=True)
    assert rebaselined == 0
    assert raw == pytest.approx(true, abs=0.02)
    assert max(abs(v) for v in SPEEDS) <= 0.5 * 1.01


def test_a_reader_starved_past_the_link_timeout_is_no_lost_link() -> None:
    """A 2.5 s stall (the host's load) is longer than link_timeout (1.5 s): the Heartbeats are
    waiting in the socket. Silence counts only as far as the reader listened (heard_until)."""
    raw, true, rebaselined, lost = drive(stamped=True, stall=2.5, heard=True)
    assert lost == 0 and rebaselined == 0
    assert raw == pytest.approx(true, abs=0.02)


def test_without_heard_until_a_starved_reader_reads_as_a_lost_link() -> None:
    _, _, rebaselined, lost = drive(stamped=True, stall=2.5, heard=False)
    assert lost >= 1 and rebaselined >= 1


def test_receive_age_believes_only_plausible_stamps() -> None:
    def msg(stamp: Any) -> can.Message:
        m = can.Message(arbitration_id=0x90, data=b"\0" * 8, is_extended_id=False)
        m.timestamp = stamp
        return m

    assert receive_age(msg(99.75), 100.0) == pytest.approx(0.25)
    for stamp in (100.5, 100.0 - MAX_RECEIVE_AGE - 1.0, math.nan, math.inf, 0.0):
        assert receive_age(msg(stamp), 100.0) == 0.0, stamp
    assert receive_age(object(), 100.0) == 0.0


def test_bus_link_hands_each_frame_with_its_age() -> None:
    import time

    stamps: list[float] = []

    class Queued:
        def recv(self, timeout: float | None = None) -> can.Message:
            m = can.Message(arbitration_id=0x90, data=b"\0" * 8, is_extended_id=False)
            m.timestamp = time.time() - 0.2  # waited 0.2 s in the socket
            stamps.append(m.timestamp)
            return m

        def shutdown(self) -> None:
            pass

    link = BusLink({"interface": "virtual", "channel": "x"}, opener=lambda cfg: Queued(),
                   clock=SimClock(), catalog_filter=False)
    ages: list[tuple[float, float | None]] = []
    link.poll(lambda fid, data: ages.append((link.last_age, link.last_received)))
    assert ages and 0.2 <= ages[0][0] < 0.2 + 1.0
    assert ages[0][1] == pytest.approx(stamps[0])  # the receive time itself, for the node


class FakeRospy:
    def __init__(self) -> None:
        self.t = 100.0

    def get_time(self) -> float:
        return self.t


def test_ros_clock_measures_clock_speed_for_the_age_of_a_frame() -> None:
    rospy, wall = FakeRospy(), [0.0]
    clock = RosClock(rospy, wall=lambda: wall[0])
    assert clock.ago(0.1) == pytest.approx(99.9)  # speed not known yet: 1
    for _ in range(3):  # /clock at 4x wall
        wall[0] += 0.5
        rospy.t += 2.0
        clock.ago(0.0)
    assert clock.rate == pytest.approx(4.0)
    assert clock.ago(0.1) == pytest.approx(rospy.t - 0.4)
    rospy.t = 10.0  # /clock restarted (a new simulation): a new window, not a negative speed
    assert clock.ago(0.0) == 10.0 and clock.rate >= 0.0


def test_a_late_sender_catching_up_in_a_burst_loses_no_motion() -> None:
    """The emulator (or firmware behind a loaded gateway) stalls 0.1 s, five wheel cycles, then
    sends them at once: the first arrives 0.1 s after the last one with the Counter one on (a
    late sender, not a reboot: those take longer than the 12-cycle gap), the rest in a burst.
    The counts are integrated and the samples stamped on the Counter's time base."""
    raw, true, rebaselined, _ = drive(stamped=False, stall=0.1)
    assert rebaselined == 0
    assert raw == pytest.approx(true, abs=0.02)


def test_a_late_senders_burst_gives_the_cycles_true_spacing() -> None:
    """/odom_raw's velocity over the burst is the wheel speed, not counts over microseconds."""
    loop = StallingLoop(stamped=False, stall=0.1)
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.READY, timeout=5.0)
    odo = loop.driver.odometry
    assert odo is not None
    speeds: list[float] = []
    loop.drive(0.5, 0.0, 3.0, on_step=lambda lp: speeds.append(odo.linear))
    assert loop.driver.stats["wheel_late_samples"] > 0
    # at most 4/3: the burst's last sample is on its receive time, within half a cycle
    assert max(speeds) < 0.5 * 1.4


def test_frames_handled_late_are_counted_and_warned_of_at_a_bounded_rate(
        caplog: pytest.LogCaptureFixture) -> None:
    """A reader behind its bus says so (it was silent more than 5 s behind, beside a CPU hog):
    each frame handed on more than LATE_HANDLING after its reception counts; one warning at
    most every 10 s of wall time sums up the ones since the last."""
    stats: Counter[str] = Counter()
    lag = HandlingLag(stats)
    with caplog.at_level(logging.WARNING, logger="lowerbase.driver.links"):
        for age, now in ((0.0, 0.0), (LATE_HANDLING, 0.5), (0.5, 1.0), (0.3, 2.0), (2.0, 5.0),
                         (0.05, 6.0), (0.4, 11.0)):
            lag.handled(age, now)
    assert stats["frames_handled_late"] == 4
    assert lag.worst == 2.0
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 2, warned
    assert "1 frame(s) handled up to 0.500 s" in warned[0]
    assert "3 frame(s) handled up to 2.000 s" in warned[1] and "(4 late in all)" in warned[1]
