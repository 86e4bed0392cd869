"""A sensor loop that cannot keep its rate says what rate it keeps (issue 22 item 16: the depth
camera published 3.7-3.9 Hz while the docs said 15 Hz, silently). A fake pace: a frame that
takes 0.25 s of its time is rendered at 4 Hz by paced_loop, which drops the ticks between."""

from __future__ import annotations

import subprocess
import sys

import pytest

from lowerbase.world.pacing import RateWatch, paced_loop
from tests.conftest import ROOT


class FakePace:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def wait_until(self, due: float) -> None:
        self.t = max(self.t, due)


def _run(frame_cost: float, seconds: float) -> tuple[RateWatch, list[str]]:
    pace, watch, lines = FakePace(), RateWatch("camera", 15.0), []

    def work() -> None:
        pace.t += frame_cost
        watch.done(pace.now())
        line = watch.report(pace.now())
        if line is not None:
            lines.append(line)

    paced_loop(pace, work, 15.0, False, lambda: pace.t < seconds, watch.dropped)
    return watch, lines


def test_a_camera_that_falls_behind_reports_the_rate_it_keeps() -> None:
    watch, lines = _run(0.25, 95.0)
    assert len(lines) == 3  # every 30 s
    assert all(line.startswith("camera: 4.0 Hz of 15 Hz over the last 30 s") for line in lines)
    assert watch.total_dropped > 0 and watch.total_done == pytest.approx(95 * 4, abs=2)


def test_a_camera_that_keeps_its_rate_says_nothing() -> None:
    watch, lines = _run(0.01, 95.0)
    assert lines == [] and watch.total_dropped == 0
    assert watch.total_done == pytest.approx(95 * 15, abs=2)


@pytest.mark.parametrize("value", ["0", "fast", "500"])
def test_camera_hz_out_of_range_is_one_line(value: str) -> None:
    out = subprocess.run([sys.executable, "-m", "lowerbase", "world", "--camera-hz", value],
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode != 0 and "Traceback" not in out.stderr
    assert "--camera-hz: must be a rate in Hz within 0.1..90" in out.stderr
