"""An emulator the host runs late (issue 22 item 3): its model keeps the time it reports. The
lower computer runs on a :class:`~lowerbase.clock.PacedClock`: late periods are caught up one
by one up to ``CATCH_UP``; a longer stall slips its time, counted in the Heartbeat's Overruns,
warned of and summed for the stop line. Every frame's Counter, Uptime and Count then agree
with one another, as firmware's do. A fake monotonic clock makes every check exact: a stall is
that clock jumping while the loop is not running."""

from __future__ import annotations

import itertools
import logging
import selectors
from typing import Any

import can
import pytest

from lowerbase.clock import CATCH_UP, PacedClock, ScaledClock, SimClock
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import run
from lowerbase.legged.lower import LeggedLower
from lowerbase.legged.profile import load_legged_profile
from lowerbase.legged.runner import run_legged
from lowerbase.protocol.codec import default_codec
from lowerbase.protocol.legged import legged_codec
from tests.firmware_model.test_scaled_clock import FakeTime, SilentBus

CODEC = default_codec()


def _paced(catch_up: float = CATCH_UP) -> tuple[FakeTime, PacedClock]:
    fake = FakeTime()
    return fake, PacedClock(ScaledClock(1.0, monotonic=fake.monotonic, wait=fake.wait),
                            catch_up=catch_up, name="test emulator")


def test_a_late_period_within_catch_up_is_no_slip() -> None:
    fake, clock = _paced()
    t0 = clock.now()
    fake.t += 0.05
    assert clock.behind() == pytest.approx(0.05)
    assert clock.enter(t0 + 0.005) == 0.0
    assert clock.now() == t0 + 0.005  # the model's time is the period's, not the wall's
    assert clock.wait_seconds(t0 + 0.01) == pytest.approx(-0.04)  # due: run it at once
    assert clock.overruns == 0 and clock.summary() == ""


def test_a_stall_beyond_catch_up_slips_the_time_and_counts(
        caplog: pytest.LogCaptureFixture) -> None:
    fake, clock = _paced()
    t0 = clock.now()
    fake.t += 0.4
    with caplog.at_level(logging.WARNING):
        slipped = clock.enter(t0 + 0.005)
        assert slipped == pytest.approx(0.395)
        assert clock.behind() == pytest.approx(0.0)  # paced from here on
        assert clock.wait_seconds(t0 + 0.010) == pytest.approx(0.005)
        fake.t += 0.3
        clock.enter(t0 + 0.010)
    assert clock.overruns == 2 and clock.slipped == pytest.approx(0.395 + 0.295)
    # one warning per SLIP_WARN_EVERY: the second slip only counts
    warnings = [r for r in caplog.records if "fell" in r.getMessage()]
    assert len(warnings) == 1 and "test emulator fell 0.395 s behind" in warnings[0].getMessage()
    assert "2 times" in clock.summary() and "0.690 s" in clock.summary()


def test_until_due_is_the_wait_and_zero_once_due() -> None:
    fake, clock = _paced()
    t0 = clock.now()
    assert clock.until_due(t0 + 0.005) == pytest.approx(0.005)
    fake.t += 0.02
    assert clock.until_due(t0 + 0.005) == 0.0  # late: due, no negative wait
    # a wait of a few ulps at a large time is due, not a spin on an unservable sleep
    fake.t = 1e6
    clock.resync()
    late = clock.now() + 1e-10
    assert 0 < clock.wait_seconds(late) <= 1e-9 and clock.until_due(late) == 0.0


def test_time_never_moves_back() -> None:
    _, clock = _paced()
    clock.enter(clock.now() + 1.0)
    with pytest.raises(ValueError, match="backwards"):
        clock.enter(clock.now() - 0.5)
    with pytest.raises(ValueError, match="catch_up"):
        PacedClock(SimClock(), catch_up=0.0)


def _moving_mcu(clock: Any, sent: list[tuple[str, dict[str, Any], float]]) -> Mcu:
    def send(frame_id: int, data: bytes) -> None:
        name, values = CODEC.decode(frame_id, data, strict=False)
        sent.append((name, values, clock.now()))

    return Mcu(load_profile(None), clock, send)


def _command(name: str, **values: Any) -> tuple[int, bytes]:
    msg = CODEC.message(name)
    return msg.frame_id, msg.encode(values)


def _run_with_stall(stall: float) -> tuple[PacedClock, list[tuple[str, dict[str, Any], float]],
                                           SilentBus, Mcu]:
    """3 s of an MCU driven at 0.4 m/s by the 50 Hz commands of an upper computer, the host
    stalled for ``stall`` s at 1.5 s."""
    fake, clock = _paced()
    sent: list[tuple[str, dict[str, Any], float]] = []
    mcu = _moving_mcu(clock, sent)
    bus = SilentBus(fake)
    steps = [0]
    enable = _command("ControlCommand", Command="EnableCanControl")

    def on_step(m: Mcu) -> None:
        steps[0] += 1
        k = steps[0]
        if k == 80:
            m.receive(*enable)
        if k >= 80 and k % 4 == 0:
            m.receive(*_command("MotionCommand", Linear=0.4, Angular=0.0, Mode="Raw",
                                Counter=k // 4 % 16))
        if k == 300:
            fake.t += stall  # the host ran something else

    run(mcu, bus, clock, duration=3.0, on_step=on_step, catalog_filter=False)
    return clock, sent, bus, mcu


@pytest.mark.parametrize("stall", [0.05, 0.4, 2.0])
def test_every_cycle_is_sent_and_counts_agree_with_velocity_across_a_stall(stall: float) -> None:
    clock, sent, _bus, mcu = _run_with_stall(stall)
    slips = 1 if stall > CATCH_UP else 0
    assert clock.overruns == slips
    # the model ran its 3 s: 600 periods, whatever the stall
    assert clock.now() - mcu.boot_time == pytest.approx(3.0, abs=1e-9)
    wheels = [(v, t) for name, v, t in sent if name == "WheelFeedback" and v["Wheel"] == 0]
    assert len(wheels) == pytest.approx(150, abs=1)  # every 20 ms cycle, none skipped
    per_pulse = mcu.profile.chassis.wheel_perimeter / (mcu.profile.chassis.ratio_left
                                                       * mcu.profile.chassis.pulse_per_circle)
    for (a, ta), (b, tb) in itertools.pairwise(wheels):
        assert (b["Counter"] - a["Counter"]) % 16 == 1
        assert tb - ta == pytest.approx(0.02, abs=1e-9)
        moved = (b["LeftCount"] - a["LeftCount"]) * per_pulse
        by_velocity = (a["LeftVelocity"] + b["LeftVelocity"]) / 2 * 0.02
        assert moved == pytest.approx(by_velocity, abs=0.0005)  # quantisation, acceleration
    beats = [v for name, v, _ in sent if name == "Heartbeat"]
    uptimes = [v["Uptime"] for v in beats]
    period = CODEC.message("Heartbeat").cycle_time
    assert all(b - a == pytest.approx(period, abs=0.0011)
               for a, b in itertools.pairwise(uptimes[1:]))  # the first: the first period's
    assert beats[0]["Overruns"] == 0 and beats[-1]["Overruns"] == slips
    # caught up period by period (no waits) within CATCH_UP; beyond, paced again at once
    assert clock.behind() == pytest.approx(0.0, abs=1e-9)
    assert clock.slipped == pytest.approx(stall - 0.005 if slips else 0.0, abs=1e-9)


def test_the_legged_lower_computer_keeps_its_uptime_across_a_stall(
        monkeypatch: pytest.MonkeyPatch) -> None:
    fake, clock = _paced()

    class Waits(selectors.DefaultSelector):  # type: ignore[misc,valid-type]
        """No bus has a descriptor: a wait passes its timeout on the fake clock."""

        def select(self, timeout: float | None = None) -> list[Any]:
            fake.t += timeout or 0.0
            return []

    monkeypatch.setattr("lowerbase.legged.runner.selectors.DefaultSelector", Waits)
    codec = legged_codec()
    beats: list[dict[str, Any]] = []

    def send(bus: int, frame_id: int, data: bytes) -> None:
        if frame_id == codec.message("Heartbeat").frame_id:
            beats.append(codec.decode(frame_id, data, strict=False)[1])

    lower = LeggedLower(load_legged_profile(None), clock, send)
    buses = [_Quiet() for _ in range(4)]
    steps = [0]

    def on_step(_: LeggedLower) -> None:
        steps[0] += 1
        if steps[0] == 500:
            fake.t += 1.5

    run_legged(lower, buses, clock, duration=2.0, on_step=on_step, catalog_filter=False)
    assert steps[0] == 2000
    assert clock.overruns == 1 and beats[-1]["Overruns"] == 1
    uptimes = [b["Uptime"] for b in beats]
    period = codec.message("Heartbeat").cycle_time
    # on the cycle, no jump of the stall's 1.5 s (the body walked what the uptime says)
    assert all(b - a == pytest.approx(period, abs=0.0011)
               for a, b in itertools.pairwise(uptimes[1:]))
    assert lower.clock.now() - lower.boot_time == pytest.approx(2.0, abs=1e-9)


class _Quiet(can.BusABC):
    """A leg bus nobody writes to, without a file descriptor (polled, no wait)."""

    def __init__(self) -> None:
        super().__init__(channel="quiet")
        self._is_shutdown = True

    def recv(self, timeout: float | None = None) -> None:
        return None

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        pass
