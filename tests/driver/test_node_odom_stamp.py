"""driver_base stamps /odom with the time of the wheel sample it describes, not with the time
it publishes it: a reader that fell behind (a busy host, ``lowerbase robot --sim-time``) hands a
backlog of frames over at once, and the world and navigation pair each scan with /odom *by
stamp*. Checked on the emulator's ground truth: SimLoop (emulator and DriverCore on a simulated
clock, ROS time = that clock as under /use_sim_time) with the node's own frame path."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import pytest

from lowerbase.driver.core import LinkState
from lowerbase.driver.settings import load_settings
from lowerbase.simloop.loop import SimLoop

BACKLOG = 0.5  #: [s] the reader stalls this long, then reads what waited in the socket
BMS_FRAMES = ("BmsStatus", "BmsPack", "BmsCapacity", "BmsCell", "BmsLife")  #: a 1 Hz burst


@pytest.fixture(autouse=True)
def no_wall_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """The node adds the wall time a frame waited for its lock to the frame's age; here the
    waits are the test's (``last_age``) and the lock is free: the wall clock stands still."""
    from lowerbase.driver import node as node_module

    monkeypatch.setattr(node_module, "time", SimpleNamespace(time=lambda: 0.0))


class StubLink:
    description = "frames handed over by the test"
    last_age = 0.0  #: [s] how long the frame being handled waited (its receive stamp's age)
    last_received: float | None = None  #: [s, wall] when, if known (then it wins)

    def send(self, frame_id: int, data: bytes) -> None:
        pass

    def close(self) -> None:
        pass


def test_odom_after_a_backlog_carries_the_stamp_of_its_wheel_sample(woosh_msgs: Any) -> None:
    import rospy

    from lowerbase.driver.node import DriverNode

    loop = SimLoop(bms=None)
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.READY, timeout=3.0)
    loop.drive(0.4, 0.0, 2.0)  # at 0.4 m/s: a stamp 0.5 s off is 0.2 m off
    settings, config = load_settings({})
    link = StubLink()
    node = DriverNode(settings, config, link, clock=loop.clock)
    node.core = loop.driver  # the node's frame path and publishing around SimLoop's core
    loop.driver.listeners.append(node._on_event)
    node.rospy = SimpleNamespace(Time=SimpleNamespace(
        now=lambda: rospy.Time.from_sec(loop.clock.now())), Duration=rospy.Duration)
    sent: list[Any] = []
    node._pubs = {"odom": SimpleNamespace(publish=sent.append)}
    truth: list[tuple[float, float]] = []  # (time, true x) at every control period
    held: list[tuple[float, int, bytes]] = []
    for _ in range(round(BACKLOG / loop.mcu.dt)):  # the reader stalls: frames wait
        loop.driver.set_twist(0.4, 0.0)
        for frame_id, data in loop._to_mcu:
            loop.mcu.receive(frame_id, data)
        loop._to_mcu.clear()
        loop.mcu.step()
        held += loop._to_driver
        loop._to_driver = []
        truth.append((loop.clock.now(), loop.mcu.truth.x))
        loop.clock.advance(loop.mcu.dt)
    for received, frame_id, data in held:  # handed over at once, each with its age
        link.last_age = loop.clock.now() - received
        node.on_frame(frame_id, data)
    assert len(sent) >= 0.8 * BACKLOG / 0.02  # /odom for (nearly) every 50 Hz wheel sample
    times = [t for t, _ in truth]
    xs = [x for _, x in truth]
    x0 = loop.driver.ekf.pose[0] - xs[-1]  # odom's offset from the truth (same heading)
    for msg in sent:
        stamp = msg.header.stamp.to_sec()
        assert times[0] - 0.03 <= stamp <= times[-1] + 1e-6, (stamp, times[0], times[-1])
        k = min(range(len(times)), key=lambda i: abs(times[i] - stamp))
        # the pose is the truth's at its stamp (within a wheel cycle's travel)
        assert math.isclose(msg.pose.pose.position.x - x0, xs[k], abs_tol=0.02), (stamp, k)


def test_odom_stamps_never_go_back_after_the_ekf_lost_its_stamp(woosh_msgs: Any) -> None:
    """The world and navigation keep /odom's history by stamp and restart it when a stamp goes
    back (a restarted /clock): an EKF reset (stamp unknown: published at "now") followed by a
    sample from before that must not look like one."""
    import rospy

    from lowerbase.clock import SimClock
    from lowerbase.driver.node import DriverNode

    clock = SimClock()
    settings, config = load_settings({})
    node = DriverNode(settings, config, StubLink(), clock=clock)
    node.rospy = SimpleNamespace(Time=SimpleNamespace(
        now=lambda: rospy.Time.from_sec(clock.now()), from_sec=rospy.Time.from_sec),
        Duration=rospy.Duration)
    sent: list[Any] = []
    node._pubs = {"odom": SimpleNamespace(publish=sent.append)}
    clock.advance(10.0)
    node.core.ekf.stamp = None  # reset: the pose's time unknown
    node._publish_odometry()
    node.core.ekf.stamp = 9.9  # the next sample, received 0.1 s ago
    node._publish_odometry()
    node.core.ekf.stamp = 10.02
    clock.advance(0.05)
    node._publish_odometry()
    assert [m.header.stamp.to_sec() for m in sent] == pytest.approx([10.0, 10.0, 10.02])


def backlog_of(loop: SimLoop, key: str, seconds: float) -> tuple[list[Any], list[Any]]:
    """A DriverNode around ``loop``'s core (ROS time = its clock) publishing ``key`` into the
    first list returned; the lower computer runs ``seconds`` while the reader stalls, and the
    frames that waited (the second list: receive time, ID, data) are handed over at once,
    each with its age."""
    import rospy

    from lowerbase.driver.node import DriverNode

    settings, config = load_settings({})
    link = StubLink()
    node = DriverNode(settings, config, link, clock=loop.clock)
    node.core = loop.driver
    loop.driver.listeners.append(node._on_event)
    node.rospy = SimpleNamespace(Time=SimpleNamespace(
        now=lambda: rospy.Time.from_sec(loop.clock.now()), from_sec=rospy.Time.from_sec),
        Duration=rospy.Duration)
    sent: list[Any] = []
    node._pubs = {key: SimpleNamespace(publish=sent.append)}
    held: list[tuple[float, int, bytes]] = []
    for _ in range(round(seconds / loop.mcu.dt)):  # the reader stalls: frames wait
        loop.mcu.step()
        held += loop._to_driver
        loop._to_driver = []
        loop.clock.advance(loop.mcu.dt)
    for received, frame_id, data in held:  # handed over at once, each with its age
        link.last_age = loop.clock.now() - received
        node.on_frame(frame_id, data)
    if key == "battery":
        node.publish_periodic()
    return sent, held


def test_imu_after_a_backlog_carries_the_stamp_of_its_frame(woosh_msgs: Any) -> None:
    """/imu/data_raw likewise: a backlog handed over at once keeps each sample's own time
    (its frame's receive stamp), 10 ms apart as the lower computer sent them, not the instant
    the node got to it (it was stamped so: on a busy host 100 samples spanned 0.9 s)."""
    loop = SimLoop(bms=None)
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.READY, timeout=3.0)
    sent, held = backlog_of(loop, "imu", BACKLOG)
    gyro_id = loop.driver.codec.message("ImuGyro").frame_id
    sent_at = [t for t, frame_id, _ in held if frame_id == gyro_id]
    stamps = [m.header.stamp.to_sec() for m in sent]
    assert len(sent_at) == round(BACKLOG / 0.01) and len(stamps) >= len(sent_at)
    # each gyro sample's message carries its frame's time (ImuAccel's, 0 s apart, may share it)
    assert all(any(abs(s - t) < 1e-9 for s in stamps) for t in sent_at), (stamps, sent_at)
    assert stamps == sorted(stamps) and stamps[-1] < loop.clock.now() - 0.004


def test_battery_after_a_backlog_carries_the_stamp_of_its_burst(woosh_msgs: Any) -> None:
    """/battery (and /driver_base/bms) carry the time their BMS burst came, not the instant
    the node published it: a backlog handed over late, the last burst keeps its own time."""
    loop = SimLoop()  # with its BMS: a burst of five frames every second
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.READY, timeout=3.0)
    sent, held = backlog_of(loop, "battery", 1.5)
    bms_ids = {loop.driver.codec.message(n).frame_id for n in BMS_FRAMES}
    bursts = [t for t, frame_id, _ in held if frame_id in bms_ids]
    assert bursts, "no BMS burst in the backlog"
    [msg] = sent
    assert max(bursts) < loop.clock.now() - 0.1
    assert msg.header.stamp.to_sec() == pytest.approx(max(bursts), abs=1e-6), (
        msg.header.stamp.to_sec(), bursts, loop.clock.now())


def test_a_frame_that_waited_for_the_lock_is_stamped_when_it_arrived(
        monkeypatch: pytest.MonkeyPatch, woosh_msgs: Any) -> None:
    """The reader hands a frame over while the tick holds the node's lock (a busy host can
    deschedule the tick for seconds): the frame's time is when the bus received it, not when
    the lock came free. Stamped late, a Heartbeat's Uptime looked 0.8 s behind its timeline;
    several in a row made the driver see reboots that never happened, beside a CPU hog."""
    from lowerbase.clock import SimClock
    from lowerbase.driver import node as node_module
    from lowerbase.driver.node import DriverNode

    clock = SimClock(100.0)  # the wall clock too, here
    monkeypatch.setattr(node_module, "time", SimpleNamespace(time=clock.now))
    settings, config = load_settings({})
    link = StubLink()
    node = DriverNode(settings, config, link, clock=clock)
    seen: list[float | None] = []
    node.core.on_frame = lambda frame_id, data, stamp=None: seen.append(stamp)  # type: ignore[method-assign]

    class HeldLock:
        """The tick keeps the lock 0.8 s after the frame came to it."""

        def __enter__(self) -> None:
            clock.advance(0.8)

        def __exit__(self, *exc: object) -> None:
            pass

    node.lock = HeldLock()  # type: ignore[assignment]
    link.last_age = 0.1  # it waited 0.1 s in the socket before the reader took it
    node.on_frame(0x90, bytes(8))
    link.last_received = 100.8 - 0.3  # received 0.3 s ago, when the reader stamps it
    clock.advance(0.5)  # the reader was descheduled before handing it over (a busy host)
    node.on_frame(0x90, bytes(8))
    assert seen == [pytest.approx(100.0 - 0.1), pytest.approx(100.5)]
    # the second is 1.6 s late: counted and warned of (the first's reception is not known)
    assert node.core.stats["frames_handled_late"] == 1
    assert node.lag.worst == pytest.approx(1.6)
