"""driver_base on ROS time (lowerbase.driver.rostime) against a stand-in rospy whose time moves
only when the test publishes a /clock: the clock reads it, sleeps until /clock passes the
deadline (woken by rospy's time condition), and the main loop's pacer ticks once per period
of that time, however fast it runs."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace
from typing import Any

import pytest

from lowerbase.clock import SimClock
from lowerbase.driver.rostime import Pacer, RosClock, uses_sim_time, wait_for_clock


class FakeRospy:
    """rospy's time API under /use_sim_time: ``get_time`` is the last /clock."""

    def __init__(self, sim: bool = True) -> None:
        self.t = 0.0
        self.shutdown = False
        cond = threading.Condition()
        self.rostime = SimpleNamespace(get_rostime_cond=lambda: cond,
                                       is_wallclock=lambda: not sim)
        self._cond = cond

    def get_time(self) -> float:
        return self.t

    def is_shutdown(self) -> bool:
        return self.shutdown

    def clock(self, t: float) -> None:
        """A /clock message arrives."""
        with self._cond:
            self.t = t
            self._cond.notify_all()


def _in_thread(target: Any) -> threading.Thread:
    th = threading.Thread(target=target, daemon=True)
    th.start()
    return th


def test_now_is_ros_time() -> None:
    rospy = FakeRospy()
    clock = RosClock(rospy)
    rospy.clock(12.34)
    assert clock.now() == 12.34
    assert uses_sim_time(rospy) and not uses_sim_time(FakeRospy(sim=False))


def test_sleep_until_returns_once_clock_passes_the_deadline() -> None:
    rospy = FakeRospy()
    clock = RosClock(rospy)
    rospy.clock(1.0)
    woke: list[float] = []
    def sleeper() -> None:
        clock.sleep_until(1.1)
        woke.append(rospy.get_time())

    th = _in_thread(sleeper)
    for t in (1.02, 1.04, 1.06, 1.08):
        rospy.clock(t)
    time.sleep(0.05)  # not a timing assertion: the sleeper must still be asleep now
    assert woke == [] and th.is_alive()
    rospy.clock(1.1)
    th.join(10.0)
    assert woke == [1.1]


@pytest.mark.parametrize("how", ["stop", "shutdown"])
def test_sleep_until_ends_on_stop_or_shutdown(how: str) -> None:
    rospy = FakeRospy()
    clock = RosClock(rospy)
    th = _in_thread(lambda: clock.sleep_until(100.0))
    if how == "stop":
        clock.stop.set()
    else:
        rospy.shutdown = True
    th.join(10.0)
    assert not th.is_alive() and rospy.get_time() == 0.0


def test_wait_for_clock_blocks_until_the_first_clock() -> None:
    rospy = FakeRospy()
    said: list[str] = []
    result: list[bool] = []
    th = _in_thread(lambda: result.append(wait_for_clock(rospy, threading.Event(),
                                                         said.append)))
    rospy.clock(0.02)
    th.join(10.0)
    assert result == [True] and "waiting for /clock" in said[0]
    # wall time, or a clock already there: no wait, nothing said
    assert wait_for_clock(FakeRospy(sim=False), threading.Event(), said.append)
    assert len(said) == 1
    stop = threading.Event()
    stop.set()
    assert wait_for_clock(FakeRospy(), stop, said.append) is False


def test_pacer_ticks_once_per_period_of_ros_time() -> None:
    """The 20 Hz loop against /clock at 50 Hz of sim time: 20 ticks per simulated second,
    each at or after its deadline, whatever the wall time it takes."""
    rospy = FakeRospy()
    rospy.clock(5.0)
    clock = RosClock(rospy)
    pacer = Pacer(clock, 0.05, clock.stop)
    ticks: list[float] = []

    def loop() -> None:
        while not clock.stop.is_set():
            pacer.wait()
            if not clock.stop.is_set():
                ticks.append(rospy.get_time())

    th = _in_thread(loop)
    deadline = time.monotonic() + 30.0
    for k in range(1, 51):  # one simulated second of /clock, 20 ms apart
        # the loop has seen every deadline up to the last /clock before the next comes
        while len(ticks) < int((k - 1) * 0.02 / 0.05 + 1e-9) and time.monotonic() < deadline:
            time.sleep(0.001)
        rospy.clock(5.0 + 0.02 * k)
    while len(ticks) < 20 and time.monotonic() < deadline:
        time.sleep(0.001)
    clock.stop.set()
    th.join(10.0)
    assert len(ticks) == 20
    assert all(t >= 5.0 + 0.05 * (k + 1) - 1e-9 for k, t in enumerate(ticks))
    assert ticks[-1] == pytest.approx(6.0)


def test_pacer_does_not_burst_after_a_stall_and_follows_a_clock_that_went_back() -> None:
    clock = SimClock(10.0)
    stop = threading.Event()
    stop.set()  # the real-clock branch waits on it: return at once
    pacer = Pacer(clock, 0.05, stop)
    clock.advance(5.0)  # a 5 s stall
    pacer.wait()
    assert pacer.deadline == 15.0  # restarted at now, not 10.05 (99 ticks of catching up)
    rospy = FakeRospy()
    rospy.clock(100.0)
    ros = RosClock(rospy)
    ros.stop.set()
    back = Pacer(ros, 0.05, ros.stop)
    rospy.clock(3.0)  # a new simulation started its /clock again
    back.wait()
    assert back.deadline == 3.0
