"""safety.watchdog on a busy host: a late try whose reception the host disturbed (a stall of the
lower computer or of this process: MotionState came in a burst; or the lower computer's own
Overruns) is measured again, with the limits unchanged. Found beside 12 busy processes:
test_emulator_passes_the_physics_with_any_seed failed 2 of 9, "SystemStatus WatchdogStop after
0.808 s, limit 0.760 s", on a correct emulator."""

from __future__ import annotations

from typing import Any

import pytest

from lowerbase.conformance import safety
from lowerbase.conformance.context import Context
from lowerbase.conformance.core import CheckFailed, Status
from lowerbase.conformance.lower_client import Received
from lowerbase.protocol.codec import default_codec

CODEC = default_codec()
CYCLE = CODEC.message("MotionState").cycle_time or 0.02
TIMEOUT = 0.5  #: [s] commandTimeout
SPEED = 0.3  #: [m/s]


class _Client:
    """Frames of the tries so far; try k starts at t = 10 k (its last MotionCommand)."""

    def __init__(self) -> None:
        self.got: dict[str, list[Received]] = {"MotionState": [], "Heartbeat": [],
                                               "StatusCode": []}

    def frames(self, name: str, since: float = 0.0) -> list[Received]:
        return [f for f in self.got[name] if f.t >= since]

    def expect(self, name: str, predicate: Any = None, timeout: float = 2.0,
               since: float | None = None) -> Received | None:
        return next((f for f in self.got[name] if since is None or f.t >= since), None)


class _Ctx:
    """What check_watchdog asks of a Context; ``tries`` says how each try goes:
    (watchdog latency [s], a reception stall [s] at 0.3 s after the stop or 0, Overruns +1)."""

    def __init__(self, tries: list[tuple[float, float, bool]]) -> None:
        self.codec = CODEC
        self.settings = type("S", (), {"speed": SPEED, "jitter": 0.15, "motion": True})()
        self.client = _Client()
        self.tries = tries
        self.done = 0

    time_slipped = Context.time_slipped  # the Context's own, on these frames

    def require_motion(self) -> None:
        pass

    def parameter(self, name: str) -> float:
        return {"commandTimeout": TIMEOUT, "linearDecelLimit": 1.0}[name]

    def run_try(self) -> tuple[float, dict[str, tuple[str, Received | None]]]:
        latency, stall, slip = self.tries[self.done]
        t_stop = 10.0 * self.done
        self.done += 1
        ms = self.client.got["MotionState"]
        t = t_stop - 0.5
        while t < t_stop + 2.5:  # a frame a cycle; a stall holds them, then they come at once
            held = t_stop + 0.3 <= t < t_stop + 0.3 + stall
            ms.append(Received(t_stop + 0.3 + stall if held else t, "MotionState",
                               {"Linear": 0.0}, b""))
            t += CYCLE
        for k in range(-4, 6):
            overruns = self.done - 1 + (slip and k >= 1)
            self.client.got["Heartbeat"].append(Received(t_stop + 0.5 * k - 0.1, "Heartbeat",
                                                         {"Overruns": overruns}, b""))
        self.client.got["StatusCode"].append(Received(t_stop + latency, "StatusCode", {}, b""))

        def at(dt: float) -> Received:
            return Received(t_stop + dt, "MotionState", {}, b"")
        return t_stop, {"flag": ("SystemStatus WatchdogStop", at(latency)),
                        "brake": ("MotionState braking", at(latency + 0.02)),
                        "still": ("MotionState standstill", at(latency + 0.3))}


@pytest.fixture
def ctx(monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest) -> _Ctx:
    c = _Ctx(request.param)
    monkeypatch.setattr(safety, "_watchdog_try", lambda ctx, limits: ctx.run_try())
    return c


ON_TIME, LATE = 0.55, 0.81  # [s] the limit is 0.5 + a control period + 0.15 + 0.1


@pytest.mark.parametrize(("ctx", "tries"), [
    ([(ON_TIME, 0.0, False)], 1),
    ([(LATE, 0.12, False), (ON_TIME, 0.0, False)], 2),  # a stall: measured again
    ([(LATE, 0.0, True), (ON_TIME, 0.0, False)], 2),  # the lower computer slipped
    ([(ON_TIME, 0.12, False)], 1),  # disturbed but on time: nothing to measure again
], indirect=["ctx"])
def test_a_try_the_host_disturbed_is_measured_again(ctx: _Ctx, tries: int) -> None:
    got = safety.check_watchdog(ctx)  # type: ignore[arg-type]
    assert got.status is Status.PASS and ctx.done == tries
    assert got.measured.get("host_disturbed_tries", 0) == tries - 1
    assert got.measured["watchdog_s"] == pytest.approx(ON_TIME)


@pytest.mark.parametrize("ctx", [[(LATE, 0.0, False)] * 3], indirect=True)
def test_a_late_watchdog_on_an_undisturbed_host_fails_at_once(ctx: _Ctx) -> None:
    with pytest.raises(CheckFailed, match=r"WatchdogStop after 0\.810 s, limit 0\.760 s"
                       ) as exc:
        safety.check_watchdog(ctx)  # type: ignore[arg-type]
    assert ctx.done == 1 and "host_disturbed_tries" not in exc.value.measured


@pytest.mark.parametrize("ctx", [[(LATE, 0.12, False)] * 3], indirect=True)
def test_every_try_disturbed_is_judged_as_measured(ctx: _Ctx) -> None:
    with pytest.raises(CheckFailed, match=r"after 0\.810 s.*measured again after 2 tries the host "
                       r"disturbed: MotionState came 0\.1[2-4]\d s apart") as exc:
        safety.check_watchdog(ctx)  # type: ignore[arg-type]
    assert ctx.done == safety.WATCHDOG_TRIES == 3
    assert exc.value.measured["host_disturbed_tries"] == 2
