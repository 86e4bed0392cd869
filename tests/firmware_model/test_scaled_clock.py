"""ScaledClock (``lowerbase emulate --speed K``): its time is K x the monotonic time since it
started, its sleeps are K times shorter, and the MCU runner's real-time loop keeps the control
period in the clock's time while waiting on the bus in wall seconds. A fake monotonic clock
makes every check exact."""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import can
import pytest

from lowerbase.clock import RealClock, ScaledClock, SimClock, real_seconds
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import run
from lowerbase.simloop.truth import TruthHook
from tests.conftest import ROOT


class FakeTime:
    """A monotonic clock that moves only when something waits on it."""

    def __init__(self, start: float = 1000.0) -> None:
        self.t = start
        self.waits: list[float] = []

    def monotonic(self) -> float:
        return self.t

    def wait(self, seconds: float) -> None:
        self.waits.append(seconds)
        self.t += seconds


@pytest.mark.parametrize("factor", [0.5, 1.0, 2.0, 4.0, 7.5])
def test_now_is_factor_times_the_monotonic_time_since_start(factor: float) -> None:
    fake = FakeTime()
    clock = ScaledClock(factor, monotonic=fake.monotonic, wait=fake.wait)
    assert clock.now() == 0.0
    fake.t += 1.25
    assert clock.now() == pytest.approx(factor * 1.25)
    assert clock.is_simulated is False


@pytest.mark.parametrize("factor", [0.5, 2.0, 4.0])
def test_sleep_until_waits_the_span_divided_by_the_factor(factor: float) -> None:
    fake = FakeTime()
    clock = ScaledClock(factor, monotonic=fake.monotonic, wait=fake.wait)
    fake.t += 0.1  # now() = 0.1 * factor
    clock.sleep_until(3.0)
    assert fake.waits == [pytest.approx((3.0 - 0.1 * factor) / factor)]
    assert clock.now() == pytest.approx(3.0)
    clock.sleep_until(2.0)  # in the past: no wait
    clock.sleep_until(3.0)  # now: no wait
    assert len(fake.waits) == 1


def test_sleep_until_returns_when_the_stop_event_is_set() -> None:
    stop = threading.Event()
    stop.set()
    clock = ScaledClock(2.0, stop)
    clock.sleep_until(clock.now() + 3600.0)  # an hour of clock time: returns at once
    assert clock.now() < 3600.0


@pytest.mark.parametrize("factor", [0.0, -1.0, math.inf, math.nan])
def test_a_factor_that_is_not_a_finite_positive_number_is_refused(factor: float) -> None:
    with pytest.raises(ValueError, match="speed factor"):
        ScaledClock(factor)


def test_real_seconds_of_each_clock() -> None:
    assert real_seconds(ScaledClock(4.0), 0.01) == pytest.approx(0.0025)
    assert real_seconds(ScaledClock(0.5), 0.01) == pytest.approx(0.02)
    assert real_seconds(RealClock(), 0.01) == 0.01
    assert real_seconds(SimClock(), 0.01) == 0.01


class SilentBus(can.BusABC):
    """A bus nobody writes to: ``recv(timeout)`` passes ``timeout`` on the fake clock."""

    def __init__(self, fake: FakeTime) -> None:
        self.fake = fake
        self.timeouts: list[float] = []
        super().__init__(channel="fake")
        self._is_shutdown = True  # nothing to release

    def recv(self, timeout: float | None = None) -> None:
        self.timeouts.append(timeout or 0.0)
        self.fake.t += timeout or 0.0
        return None

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        pass


@pytest.mark.parametrize("factor", [1.0, 2.0, 4.0])
def test_the_runner_keeps_the_period_in_clock_time_and_waits_in_wall_time(
        factor: float) -> None:
    fake = FakeTime()
    clock = ScaledClock(factor, monotonic=fake.monotonic, wait=fake.wait)
    mcu = Mcu(load_profile(None), clock, lambda frame_id, data: None)
    bus = SilentBus(fake)
    steps: list[float] = []
    wall0 = fake.t
    run(mcu, bus, clock, duration=2.0, on_step=lambda m: steps.append(clock.now()),
        catalog_filter=False)
    n = round(2.0 / mcu.dt)
    assert len(steps) == n
    # one step per period of clock time, at the period's end
    assert steps == pytest.approx([(k + 1) * mcu.dt for k in range(n)], abs=1e-9)
    # 2 s of clock time took 2 / factor s of (fake) wall time, in bus waits of dt / factor
    assert fake.t - wall0 == pytest.approx(2.0 / factor)
    assert max(bus.timeouts) == pytest.approx(mcu.dt / factor)


def _emulate(*args: str, **kw: Any) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "lowerbase", "emulate", *args],
                          capture_output=True, text=True, cwd=ROOT, timeout=120, **kw)


def test_emulate_speed_runs_the_truth_on_the_sped_up_time(tmp_path: Path) -> None:
    truth = tmp_path / "truth.csv"
    out = _emulate("-i", "virtual", "-c", "simtime-speed", "--speed", "4", "--duration", "2",
                   "--truth", str(truth))
    assert out.returncode == 0, out.stderr
    assert "4 x real time" in out.stdout
    rows = truth.read_text().splitlines()
    t = [float(r.split(",")[0]) for r in rows[1:]]
    # --duration and the 50 Hz sampling are in the clock's time: 2 s of it, about a row per
    # 20 ms (a loaded host makes the 4x loop late or skip periods: the exact grid is the hook's
    # deterministic test below)
    assert t[-1] - t[0] == pytest.approx(2.0, abs=0.08)
    assert 50 <= len(t) <= 101


class _Stepped:
    def __init__(self) -> None:
        self.clock = SimClock(5.0)
        self.boot_time = 5.0


class _Hook(TruthHook):
    def __init__(self) -> None:
        super().__init__(0.02)
        self.times: list[float] = []

    def emit(self, mcu: Any, t: float) -> None:
        self.times.append(t)


def test_the_truth_hook_keeps_its_rate_when_steps_come_late() -> None:
    """Each step is seen 0..4 ms after its 5 ms boundary (a real-time loop's latency, x K
    on --speed K): the samples stay on average one per 20 ms, none closer than 16 ms."""
    mcu, hook = _Stepped(), _Hook()
    for k in range(2000):  # 10 s of 5 ms steps
        late = (k * 7919 % 5) * 0.001
        mcu.clock.sleep_until(5.0 + (k + 1) * 0.005 + late)
        hook(mcu)
        mcu.clock = SimClock(5.0 + (k + 1) * 0.005)  # back to the boundary (the deadline)
    assert len(hook.times) == pytest.approx(500, abs=1)
    gaps = [b - a for a, b in itertools.pairwise(hook.times)]
    assert min(gaps) >= 0.016 - 1e-9 and max(gaps) <= 0.024 + 1e-9


def test_the_truth_hook_restarts_its_grid_after_a_stall_without_a_burst() -> None:
    mcu, hook = _Stepped(), _Hook()
    for t in (5.0, 5.02, 5.04, 6.0, 6.005, 6.01, 6.015, 6.02, 6.04):
        mcu.clock = SimClock(t)
        hook(mcu)
    assert hook.times == pytest.approx([0.0, 0.02, 0.04, 1.0, 1.02, 1.04])


@pytest.mark.parametrize(("argv", "text"), [
    (["--speed", "0"], "--speed: must be a number > 0"),
    (["--speed", "fast"], "--speed: must be a number > 0"),
    (["--speed", "-2"], "--speed: must be a number > 0"),
    (["--speed", "2", "--simulated", "--duration", "1"], "drop one of them"),
    (["--speed", "2", "--robot", "legged"], "--speed is for the wheeled robot"),
])
def test_emulate_speed_errors_are_one_line(argv: list[str], text: str) -> None:
    out = _emulate("-i", "virtual", "-c", "simtime-bad", *argv)
    assert out.returncode != 0
    assert "Traceback" not in out.stderr
    lines = [line for line in out.stderr.strip().splitlines() if text in line]
    assert lines, out.stderr
