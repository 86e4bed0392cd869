"""The status line's sim time and speed (lowerbase.robot.simclock.ClockWatch), on given wall
times: the ratio is sim seconds over wall seconds across the last window."""

from __future__ import annotations

import pytest

from lowerbase.robot.simclock import ClockWatch


def test_before_any_clock() -> None:
    watch = ClockWatch()
    assert watch.sim is None and watch.ratio() is None
    assert watch.status() == "sim time: waiting for /clock"
    watch.add(1.0, wall=100.0)
    assert watch.sim == 1.0 and watch.ratio() is None


@pytest.mark.parametrize("k", [0.5, 2.0, 4.0])
def test_ratio_over_the_window(k: float) -> None:
    watch = ClockWatch(window=5.0)
    for i in range(1000):  # 10 s of wall time, /clock every 10 ms of it
        watch.add(3.0 + k * 0.01 * i, wall=50.0 + 0.01 * i)
    assert watch.ratio() == pytest.approx(k)
    assert watch.sim == pytest.approx(3.0 + k * 9.99)
    assert watch.status() == f"sim {3.0 + k * 9.99:.1f} s ({k:.2f} x real time)"


def test_the_window_forgets_a_slow_start() -> None:
    watch = ClockWatch(window=5.0)
    for i in range(100):  # 1 s of wall, the simulation stalled
        watch.add(1.0, wall=float(i) * 0.01)
    for i in range(1, 1001):  # then 10 s at 3 x
        watch.add(1.0 + 3 * 0.01 * i, wall=1.0 + 0.01 * i)
    assert watch.ratio() == pytest.approx(3.0)


def test_a_restarted_clock_is_measured_afresh() -> None:
    watch = ClockWatch()
    for i in range(100):
        watch.add(50.0 + 0.02 * i, wall=0.01 * i)
    watch.add(0.02, wall=1.0)
    watch.add(0.06, wall=1.01)
    assert watch.sim == 0.06 and watch.ratio() == pytest.approx(4.0)
