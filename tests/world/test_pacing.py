"""The world node's sensor loop (lowerbase.world.pacing) on a clock the test moves: its rate is
per second of THAT clock (sim time under /use_sim_time), late ticks are caught up or dropped
and counted, a clock that goes backwards restarts the schedule. ROS-free."""

from __future__ import annotations

import itertools
import threading

import pytest

from lowerbase.world.pacing import WallPace, pace_for, paced_loop


class StepClock:
    """A clock that moves only when a wait needs it to (each /clock arriving just in time)."""

    def __init__(self, t: float = 100.0) -> None:
        self.t = t
        self.waits = 0

    def now(self) -> float:
        return self.t

    def wait_until(self, due: float) -> None:
        self.waits += 1
        self.t = max(self.t, due)


def test_the_rate_is_per_second_of_the_paces_clock() -> None:
    clock = StepClock()
    ticks: list[float] = []
    paced_loop(clock, lambda: ticks.append(clock.t), 25.0, True, lambda: clock.t < 110.0)
    per_s = (len(ticks) - 1) / (ticks[-1] - ticks[0])
    assert abs(per_s - 25.0) < 0.01 and ticks[0] == 100.0


def test_a_late_scan_is_caught_up_and_a_late_frame_dropped_and_counted() -> None:
    for catch_up in (True, False):
        clock = StepClock()
        ticks: list[float] = []
        drops: list[int] = []

        def work(ticks: list[float] = ticks, clock: StepClock = clock) -> None:
            ticks.append(clock.t)
            if len(ticks) == 3:
                clock.t += 0.5  # one slow tick: 0.5 s of that clock

        def running(c: StepClock = clock) -> bool:
            return c.t < 102.0

        paced_loop(clock, work, 10.0, catch_up, running, drops.append)
        if catch_up:  # the missed ticks run at once, back to back, then the schedule goes on
            assert ticks[3:8] == pytest.approx([100.7] * 5) and not drops
            assert abs(len(ticks) - 21) <= 1
        else:
            assert drops == [4] and ticks[3:5] == pytest.approx([100.7, 100.8])


def test_a_clock_going_backwards_restarts_the_schedule() -> None:
    clock = StepClock()
    ticks: list[float] = []

    def work() -> None:
        ticks.append(clock.t)
        if len(ticks) == 5:
            clock.t = 10.0  # a /clock restarted near 0 by someone else

    paced_loop(clock, work, 25.0, True, lambda: len(ticks) < 12)
    assert ticks[5] == 10.0 and all(b > a for a, b in itertools.pairwise(ticks[5:]))


def test_wall_pace_stops_at_once() -> None:
    stop = threading.Event()
    stop.set()
    pace = WallPace(stop)
    pace.wait_until(pace.now() + 3600.0)  # would hang for an hour if stop were not looked at


class FakeRospy:
    def __init__(self, sim: object) -> None:
        self.sim = sim

    def get_param(self, name: str, default: object) -> object:
        assert name == "/use_sim_time"
        return self.sim


def test_ros_time_only_under_use_sim_time() -> None:
    stop = threading.Event()
    assert type(pace_for(FakeRospy(True), stop)).__name__ == "RosPace"
    assert isinstance(pace_for(FakeRospy(False), stop), WallPace)
