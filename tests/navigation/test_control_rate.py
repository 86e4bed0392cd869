"""move_base's control loop on wall time misses its rate rather than catching up, and says so:
ticks run back to back after a stall would all see the same pose and time (a burst of the same
cmd_vel), and a loop that silently fell to a lower rate is what the field trial found on a busy
host. On ROS time (lockstep, /use_sim_time) every tick of the clock's time still runs."""

from __future__ import annotations

import logging

import pytest

from lowerbase.navigation.loop import control_loop
from lowerbase.world.pacing import RateWatch
from tests.world.test_rate_watch import FakePace


class _Rates:
    rate_hz = 20.0
    costmap_rate_hz = 2.0


def _run(tick_cost: float, seconds: float) -> tuple[list[float], RateWatch]:
    pace, ticks = FakePace(), []
    watch = RateWatch("move_base control loop", 20.0, what="tick")

    def tick(now: float) -> None:
        ticks.append(now)
        pace.t += tick_cost

    control_loop(pace, tick, lambda _: None, _Rates(), lambda: pace.t < seconds, watch)
    return ticks, watch


def test_a_slow_control_loop_misses_ticks_counts_them_and_warns(
        caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="lowerbase.navigation.loop"):
        ticks, watch = _run(0.08, 65.0)  # a tick takes 80 ms of a 50 ms period: 12.5 Hz
    assert len(ticks) == pytest.approx(65 * 12.5, abs=2)
    assert watch.total_dropped == pytest.approx(65 * 7.5, abs=2)
    # every period of the schedule is either a tick or a counted miss
    assert len(ticks) + watch.total_dropped == pytest.approx(65 * 20, abs=2)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and all(line.startswith(
        "move_base control loop: 12.5 Hz of 20 Hz over the last 30 s (") for line in lines)
    assert "ticks dropped: a tick takes longer than a period" in lines[0]


def test_a_control_loop_that_keeps_its_rate_says_nothing(
        caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="lowerbase.navigation.loop"):
        ticks, watch = _run(0.01, 65.0)
    assert len(ticks) == pytest.approx(65 * 20, abs=1) and watch.total_dropped == 0
    assert caplog.records == []
