"""The wheel-count check's time base: the WheelFeedback Counter's span, unless the sender
skipped cycles (tests/conformance/test_conformance_defects.py once failed physics.wheel_count on a
loaded host: a 16-cycle gap wrapped the 4-bit Counter and the span came out 21 % short)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from lowerbase.conformance.catalog import WheelSample
from lowerbase.conformance.physics import _firmware_span
from lowerbase.protocol.codec import default_codec

CYCLE = default_codec().message("WheelFeedback").cycle_time or 0.02
CTX = SimpleNamespace(codec=default_codec())


def _samples(gap_at: int | None = None, gap_cycles: int = 0, jitter: float = 0.0
             ) -> list[WheelSample]:
    """75 WheelFeedback frames one cycle apart (a Counter +1 each); at ``gap_at`` the sender
    skips ``gap_cycles`` cycles (time goes on, the Counter does not)."""
    out, t = [], 0.0
    for k in range(75):
        if k == gap_at:
            t += gap_cycles * CYCLE
        out.append(WheelSample(t + (jitter if k % 2 else 0.0), 0, 0.5, k % 16))
        t += CYCLE
    return out


def test_the_counter_span_is_used_despite_reception_jitter() -> None:
    samples = _samples(jitter=0.004)
    assert _firmware_span(CTX, samples) == pytest.approx(74 * CYCLE)


@pytest.mark.parametrize("gap_cycles", [4, 8, 16, 20])
def test_a_sender_that_skipped_cycles_is_timed_by_reception(gap_cycles: int) -> None:
    samples = _samples(gap_at=40, gap_cycles=gap_cycles)
    assert _firmware_span(CTX, samples) == pytest.approx((74 + gap_cycles) * CYCLE)


def _moving(delays: dict[int, float], skip_at: int | None = None) -> list[WheelSample]:
    """75 frames of a wheel at 0.5 m/s, 1 pulse per mm: frame k sent at its cycle, received
    ``delays[k]`` s late (a busy host: later frames of a burst arrive together); at
    ``skip_at`` the sender skips 4 cycles (the count moves on, the Counter does not)."""
    out, t, count = [], 0.0, 0
    for k in range(75):
        if k == skip_at:
            t += 4 * CYCLE
            count += round(4 * CYCLE * 500)
        out.append(WheelSample(t + delays.get(k, 0.0), count, 0.5, k % 16))
        t += CYCLE
        count += round(CYCLE * 500)
    return out


def test_one_cycle_pairs_ignore_the_receiving_hosts_bursts() -> None:
    """Issue 22 item 3's CI failure: frames delivered late and then in a burst made the span
    by reception 14 % short of the counts; pairs one Counter step apart are exact."""
    from lowerbase.conformance.physics import _one_cycle_pairs

    burst = {k: 0.1 - 0.02 * (k - 30) for k in range(30, 35)}  # 5 frames held, then all at once
    pulses, metres, span = _one_cycle_pairs(CTX, _moving(burst))  # type: ignore[misc]
    assert pulses / 1000.0 == pytest.approx(metres) and span < 74 * CYCLE
    pulses, metres, _ = _one_cycle_pairs(CTX, _moving({}, skip_at=40))  # type: ignore[misc]
    assert pulses / 1000.0 == pytest.approx(metres)  # the pair across the skip is left out
