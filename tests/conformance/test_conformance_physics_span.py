"""The wheel-count check's time base: the WheelFeedback Counter's span, unless the sender
skipped cycles (tests/conformance/test_conformance_defects.py once failed physics.wheel_count on a
loaded host: a 16-cycle gap wrapped the 4-bit Counter and the span came out 21 % short)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from lowerbase.conformance import physics
from lowerbase.conformance.catalog import WheelSample
from lowerbase.conformance.context import Context
from lowerbase.conformance.core import Settings
from lowerbase.conformance.lower_client import Received
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


class _Heartbeats:
    """A LowerClient's Heartbeats: one every 0.5 s from -0.2 s, Overruns +1 at the listed
    reception times (the lower computer's time slipped just before them)."""

    def __init__(self, slips: tuple[float, ...], boot_at: float | None = None) -> None:
        self.got: list[Received] = []
        overruns, boot = 0, 1
        for k in range(20):
            t = -0.2 + 0.5 * k
            overruns += sum(1 for s in slips if t - 0.5 < s <= t)
            boot += boot_at is not None and t - 0.5 < boot_at <= t
            self.got.append(Received(t, "Heartbeat", {"Overruns": overruns % 16,
                                                      "BootCounter": boot}, b""))

    codec = default_codec()

    def frames(self, name: str, since: float = 0.0) -> list[Received]:
        return [f for f in self.got if f.t >= since and f.name == name]

    def expect(self, name: str, timeout: float = 2.0, since: float | None = None
               ) -> Received | None:
        return next((f for f in self.got if since is not None and f.t >= since
                     and f.name == name), None)


def _context(client: _Heartbeats) -> Context:
    return Context(client, Settings())  # type: ignore[arg-type]


@pytest.fixture
def windows(monkeypatch: pytest.MonkeyPatch) -> list[tuple[float, float]]:
    """The windows physics._window measures, in order (1 s each, 0.5 s apart); no sleeping."""
    given: list[tuple[float, float]] = []

    def window(ctx: object, seconds: float) -> tuple[float, float]:
        t0 = 1.5 * len(given)
        given.append((t0, t0 + seconds))
        return given[-1]

    monkeypatch.setattr(physics, "_window", window)
    return given


@pytest.mark.parametrize(("slips", "tries"), [((), 1), ((0.6,), 2), ((0.6, 2.0), 3),
                                              ((0.6, 2.0, 3.4), 3), ((-0.3, 1.35), 1)])
def test_a_window_in_which_the_lower_computer_slipped_is_measured_again(
        windows: list[tuple[float, float]], slips: tuple[float, ...], tries: int) -> None:
    """Issue 18's real-time path: physics.odometer failed on a busy host, the emulator's
    skipped WheelFeedback slots (2 of 50, under SPAN_DISAGREEMENT) making the Counter's span
    short; the Heartbeat's Overruns said so. A window with a slip is measured again (the
    motion goes on), at most WINDOW_TRIES times; slips outside the Heartbeats around a window
    do not count."""
    ctx = _context(_Heartbeats(slips))
    got = physics._steady_window(ctx)  # type: ignore[arg-type]
    assert len(windows) == tries == min(tries, physics.WINDOW_TRIES)
    assert got == windows[-1]


def test_a_reboot_or_no_heartbeat_ends_the_tries(windows: list[tuple[float, float]]) -> None:
    ctx = _context(_Heartbeats((0.6,), boot_at=0.6))
    assert physics._steady_window(ctx) == windows[0]  # type: ignore[arg-type]
    silent = _context(_Heartbeats(()))
    silent.client.got.clear()
    assert physics._steady_window(silent) == windows[1]  # type: ignore[arg-type]
    assert len(windows) == 2


def test_the_watchdogs_retry_sees_the_slip_the_heartbeats_around_its_try_report() -> None:
    """safety.watchdog measures a late try again when the lower computer's time slipped in it:
    the same Heartbeats as the physics windows (its last before, its first after the try)."""
    from lowerbase.conformance.safety import host_disturbance

    assert "Overruns" in host_disturbance(_context(_Heartbeats((1.0,))), 0.5, 1.2)
    assert host_disturbance(_context(_Heartbeats((3.0,))), 0.5, 1.2) == ""
    assert host_disturbance(_context(_Heartbeats((0.1,))), 0.5, 1.2) == ""
