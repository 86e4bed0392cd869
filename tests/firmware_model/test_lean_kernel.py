"""The compiled lean period (fastkernel.py, lean_kernel.py) against the Python loops.

The pinned frame trace (test_frame_trace.py) runs with the kernel; here: the kernel really
runs, the Python lean loop (its reference) gives the same trace, switching between the kernel
and the general loop at arbitrary periods is seamless, surroundings and slip keep the Python
truth step, and without numba the Python loop takes over.
"""

from __future__ import annotations

import sys
from typing import Any

import pytest

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.firmware_model import fastbatch, fastkernel
from lowerbase.firmware_model.fastkernel import KernelLoop
from lowerbase.firmware_model.fastloop import LeanLoop
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.truth import SlipEvent, TruePose
from lowerbase.protocol.status_codes import StatusBit
from tests.firmware_model.test_frame_trace import EXPECTED, TraceRig, record

pytestmark = pytest.mark.skipif(fastkernel.kernel() is None, reason="numba not available")


def _count_kernel_periods(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Periods done by KernelLoop.step ("kernel"), left by it to Python ("python"), and done
    in runs (fastbatch.run, "run")."""
    seen = {"kernel": 0, "python": 0, "run": 0}
    step, run = KernelLoop.step, fastbatch.run

    def counted(self: KernelLoop) -> bool:
        done = step(self)
        seen["kernel" if done else "python"] += 1
        return done

    def counted_run(kl: KernelLoop, n: int) -> int:
        done = run(kl, n)
        seen["run"] += done
        return done

    monkeypatch.setattr(KernelLoop, "step", counted)
    monkeypatch.setattr(fastbatch, "run", counted_run)
    return seen


def test_the_kernel_runs_most_lean_periods_and_keeps_the_trace(
        monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _count_kernel_periods(monkeypatch)
    assert record() == EXPECTED
    # SimRig.drive and run go through Mcu.advance; the BMS polls run in the kernel too (in
    # this drive none comes in a period that also steps the pack: see the test below)
    assert seen["run"] > seen["kernel"] > 0 and seen["python"] == 0


def test_the_python_lean_loop_gives_the_same_trace(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(LeanLoop, "compiled", False)
    seen = _count_kernel_periods(monkeypatch)
    assert record() == EXPECTED
    assert seen == {"kernel": 0, "python": 0, "run": 0}


def _drive_switching(general_every: int | None, runs: bool = False
                     ) -> tuple[list[Any], tuple[Any, ...]]:
    """A drive in which a fault is armed (not yet active: the general loop) and cleared again
    at irregular periods; every frame and the end state. ``runs``: the periods between two
    changes go through ``Mcu.advance`` (runs of compiled periods), else ``step()`` each."""
    p = load_profile()
    rig = TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery), keep=False)
    rig.enable()
    k = 0
    while k < 1400:
        if k % 4 == 0:
            rig.send("MotionCommand", Linear=0.5 + 0.001 * (k % 50), Angular=0.3 - 0.002 * (
                k % 30), Mode="Raw" if k < 500 or k > 1000 else "Smoothed")
        if general_every is not None and k % general_every in (0, 3, 4):
            if rig.mcu.faults:
                rig.mcu.clear_fault()
            else:
                rig.mcu.inject("drop:0.5@1000")  # in play, never active
        if k == 1200:  # commands stop: the watchdog brakes
            k += 200
            rig.mcu.advance(200) if runs else rig.run(1.0)
            continue
        if runs:
            n = 1 + k % 3
            rig.mcu.advance(n)
            k += n
        else:
            rig.step()
            k += 1
    rig.mcu._lean.release()  # the due times and counters the kernel holds, back to the Mcu
    m, tr = rig.mcu, rig.mcu.truth
    end = (tr.x, tr.y, tr.yaw, tr.v, tr.w, tr.accel_x, tr.distance, m.odometer,
           m.encoder_counts(), m.status, int(m.state), m.imu_sample, dict(m._counters),
           list(m._due), m.motors["left"].current, m.motors["right"].setpoint, m._bms_charge)
    return rig.trace, end


@pytest.mark.parametrize(("every", "runs"), [(7, False), (23, False), (11, True), (37, True)])
def test_switching_kernel_and_general_loop_is_seamless(monkeypatch: pytest.MonkeyPatch,
                                                       every: int, runs: bool) -> None:
    seen = _count_kernel_periods(monkeypatch)
    switching = _drive_switching(every, runs)
    assert seen["kernel"] + seen["run"] > 300
    monkeypatch.setattr(Mcu, "lean", False)
    assert switching == _drive_switching(None, runs)  # Mcu.advance: step() each


class Wall:
    """Refuses every move that ends beyond x = 0.3 m."""

    def __init__(self) -> None:
        self.asked = 0

    def allowed(self, pose_from: TruePose, pose_to: TruePose, t: float) -> bool:
        self.asked += 1
        return pose_to[0] <= 0.3


def _run(rig: TraceRig, seconds: float) -> tuple[Any, ...]:
    rig.enable()
    rig.drive(0.5, 0.0, seconds)
    tr = rig.mcu.truth
    return rig.trace, tr.x, tr.y, tr.yaw, tr.blocked_steps, rig.mcu.encoder_counts()


def test_surroundings_and_slip_events_keep_the_python_truth_step(
        monkeypatch: pytest.MonkeyPatch) -> None:
    def rig(wall: Wall) -> TraceRig:
        r = TraceRig(profile=load_profile(), keep=False)
        r.mcu.truth.surroundings = wall
        r.mcu.slip.add_event(SlipEvent("left", 0.6, 0.3, 0.4))
        return r

    walls = Wall(), Wall()
    got = _run(rig(walls[0]), 1.5)
    assert got[4] > 0 and walls[0].asked == round(1.85 / 0.005)  # asked before every move
    monkeypatch.setattr(Mcu, "lean", False)
    assert got == _run(rig(walls[1]), 1.5)


def test_without_numba_the_python_loop_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    name = "lowerbase.firmware_model.lean_kernel"
    real = sys.modules[name]
    monkeypatch.setattr(fastkernel, "_kernel", None)
    monkeypatch.setitem(sys.modules, name, None)  # import fails as without numba
    assert fastkernel.kernel() is None
    rig = TraceRig(profile=load_profile(), keep=False)
    assert rig.mcu._lean.kernel is None
    python = _run(rig, 1.0)
    monkeypatch.setattr(fastkernel, "_kernel", None)
    monkeypatch.setitem(sys.modules, name, real)
    compiled = TraceRig(profile=load_profile(), keep=False)
    assert compiled.mcu._lean.kernel is not None
    assert _run(compiled, 1.0) == python



def _drive_polled(shift: int) -> tuple[tuple[Any, ...], int]:
    """A drive on a pack near LOW_BATTERY, a charger connected midway (the CHARGING bit comes
    with a poll), the pack's step phase moved by ``shift`` periods against the polls: (frames
    and end state with the BMS's reading, how many polls came in a period that stepped the
    pack, as the step() loop calls them)."""
    p = load_profile()
    bms = McuBmsAdapter.from_battery_table(p.battery, soc=20.02)
    rig = TraceRig(profile=p, bms=bms, keep=False)
    stepped, both = [-1.0], [0]
    step, poll = bms.step, bms.poll

    def counted_step(dt: float, load_current: float) -> None:
        stepped[0] = rig.clock.now()
        step(dt, load_current)

    def counted_poll() -> Any:
        both[0] += stepped[0] == rig.clock.now()
        return poll()

    bms.step, bms.poll = counted_step, counted_poll  # type: ignore[method-assign]
    rig.mcu._bms_elapsed = shift * rig.mcu.dt
    rig.enable()
    rig.drive(0.8, 0.3, 4.0)
    bms.connect_charger()
    rig.drive(0.6, -0.2, 3.0)
    m = rig.mcu
    return (rig.trace, m.status, m._bms_bits, m._bms_last_answer, m.bms_snapshot,
            m._bms_charge, m.truth.x, m.odometer), both[0]


@pytest.mark.parametrize("shift", [0, 7, 19])
def test_bms_polls_run_in_the_kernel_unless_the_pack_steps_in_the_same_period(
        monkeypatch: pytest.MonkeyPatch, shift: int) -> None:
    seen = _count_kernel_periods(monkeypatch)
    got, _ = _drive_polled(shift)
    assert got[2] & int(StatusBit.CHARGING) and got[1] & int(StatusBit.CHARGING)
    monkeypatch.setattr(Mcu, "lean", False)
    general, both = _drive_polled(shift)  # the general loop, step by step
    assert got == general
    # only a poll in a period that also steps the pack leaves the kernel (shift 19: some do)
    assert seen["python"] == both and (both > 0) == (shift == 19)
