"""The compiled lean period (fastkernel.py, lean_kernel.py) against the Python loops.

The pinned frame trace (test_frame_trace.py) runs with the kernel; here: the kernel really
runs, the Python lean loop (its reference) gives the same trace, switching between the kernel
and the period with its fault hooks at arbitrary periods is seamless, surroundings and slip
keep the Python truth step, and without numba the Python loop takes over.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from typing import Any

import pytest

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.firmware_model import fastbatch, fastkernel
from lowerbase.firmware_model.fastkernel import KernelLoop
from lowerbase.firmware_model.fastloop import LeanLoop
from lowerbase.firmware_model.faults import Fault
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

    def counted(self: KernelLoop, hooks: bool = False) -> bool:
        done = step(self, hooks)
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
    # this drive none comes in a period that also steps the pack: see the test below), and so
    # does every period with a fault acting (each kind's data and hooks)
    assert seen["run"] > 0 and seen["kernel"] > 0 and seen["python"] == 0


def test_the_python_lean_loop_gives_the_same_trace(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(LeanLoop, "compiled", False)
    seen = _count_kernel_periods(monkeypatch)
    assert record() == EXPECTED
    assert seen == {"kernel": 0, "python": 0, "run": 0}


def _drive_switching(hooked_every: int | None, runs: bool = False
                     ) -> tuple[list[Any], tuple[Any, ...]]:
    """A drive in which a fault is injected (active but without effect: the hooked period) and
    cleared again at irregular periods; every frame and the end state. ``runs``: the periods
    between two changes go through ``Mcu.advance`` (runs of compiled periods), else
    ``step()`` each."""
    p = load_profile()
    rig = TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery), keep=False)
    rig.enable()
    k = 0
    while k < 1400:
        if k % 4 == 0:
            rig.send("MotionCommand", Linear=0.5 + 0.001 * (k % 50), Angular=0.3 - 0.002 * (
                k % 30), Mode="Raw" if k < 500 or k > 1000 else "Smoothed")
        if hooked_every is not None and k % hooked_every in (0, 3, 4):
            if rig.mcu.faults:
                rig.mcu.clear_fault()
            else:
                rig.mcu.inject("delay:0")  # active (the hooked period), changes nothing
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
def test_switching_kernel_and_hooked_period_is_seamless(monkeypatch: pytest.MonkeyPatch,
                                                       every: int, runs: bool) -> None:
    seen = _count_kernel_periods(monkeypatch)
    switching = _drive_switching(every, runs)
    assert seen["kernel"] + seen["run"] > 300
    monkeypatch.setattr(Mcu, "lean", False)
    assert switching == _drive_switching(None, runs)  # Mcu.advance: step() each


def _drive_through_a_stall() -> tuple[Any, ...]:
    """A drive through Mcu.advance with a stall armed for later (1 s from now, for 0.5 s) and
    a drop armed beyond the drive: every frame and the end state."""
    p = load_profile()
    rig = TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery), keep=False)
    rig.enable()
    mcu = rig.mcu
    t = mcu.clock.now() - mcu.boot_time
    mcu.inject(Fault("stall", "left", start=t + 1.0, duration=0.5))
    mcu.inject(Fault("drop", "0.5", start=t + 100.0))
    rig.drive(0.5, 0.2, 3.0)
    rig.drive(0.0, 0.0, 1.0)
    mcu._lean.release()
    tr = mcu.truth
    return (rig.trace, tr.x, tr.y, tr.yaw, mcu.odometer, mcu.encoder_counts(), mcu.status,
            mcu.motion_fault, int(mcu.state), dict(mcu._counters), list(mcu._due))


def test_runs_take_the_periods_before_a_fault_starts(monkeypatch: pytest.MonkeyPatch
                                                    ) -> None:
    seen = _count_kernel_periods(monkeypatch)
    got = _drive_through_a_stall()
    assert got[6] & StatusBit.LEFT_MOTOR_FAULT  # the stall happened (and latched)
    assert seen["run"] > 150  # the second before the stall: runs
    monkeypatch.setattr(Mcu, "lean", False)
    assert got == _drive_through_a_stall()


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


def test_surroundings_keep_the_python_truth_step(monkeypatch: pytest.MonkeyPatch) -> None:
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


def _slipping(events: bool, rate: float) -> TraceRig:
    p = load_profile()
    rig = TraceRig(profile=replace(p, truth=replace(
        p.truth, slip_rate_per_km=rate, slip_duration=0.05, slip_fraction=0.6)), keep=False)
    if events:
        rig.mcu.slip.add_event(SlipEvent("left", 0.6, 0.3, 0.4))
        rig.mcu.slip.add_event(SlipEvent("both", 0.8, 0.2, 0.25))
    return rig


@pytest.mark.parametrize(("events", "rate"), [(True, 0.0), (False, 3000.0), (True, 3000.0)])
def test_slip_events_and_random_slip_run_in_the_kernel(
        monkeypatch: pytest.MonkeyPatch, events: bool, rate: float) -> None:
    """The events' slip fractions (SlipModel.event_fractions, random events drawn) enter the
    kernel as data: every lean period compiled, the same frames and truth as the Python lean
    loop and the hooked period; and the slip shows (so a kernel that ignored it would differ)."""
    seen = _count_kernel_periods(monkeypatch)
    rig = _slipping(events, rate)
    got = _run(rig, 1.5)
    assert seen["kernel"] >= 200 and seen["python"] == 0  # runs after the events (1 s)
    assert got != _run(_slipping(False, 0.0), 1.5)  # the slip changed the trace
    monkeypatch.setattr(LeanLoop, "compiled", False)
    assert got == _run(_slipping(events, rate), 1.5)
    monkeypatch.setattr(LeanLoop, "compiled", True)
    monkeypatch.setattr(Mcu, "lean", False)
    assert got == _run(_slipping(events, rate), 1.5)


def _drive_with_data_faults(bms: bool = True) -> tuple[Any, ...]:
    """A drive through Mcu.advance with the left encoder failing for 0.6 s (long enough for
    its fault bit), the IMU frozen for 0.6 s from 0.1 s later, then both encoders for 0.1 s,
    then nothing: every frame and the end state."""
    p = load_profile()
    rig = TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery) if bms else None,
                   keep=False)
    rig.enable()
    mcu = rig.mcu
    t = mcu.clock.now() - mcu.boot_time
    mcu.inject(Fault("encoder", "left", start=t + 0.5, duration=0.6))
    mcu.inject(Fault("encoder", "right", start=t + 1.3, duration=0.1))
    mcu.inject(Fault("encoder", "left", start=t + 1.3, duration=0.1))
    mcu.inject(Fault("imu-freeze", start=t + 0.6, duration=0.6))
    rig.drive(0.5, 0.2, 1.0)
    bits = mcu.status
    rig.drive(0.4, -0.2, 1.5)
    mcu._lean.release()
    tr = mcu.truth
    return (rig.trace, bits, tr.x, tr.y, tr.yaw, mcu.odometer, mcu.encoder_counts(),
            mcu.status, mcu.motion_fault, int(mcu.state), dict(mcu._counters), list(mcu._due))


def test_encoder_and_imu_freeze_faults_run_in_the_kernel(monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    """The encoder faults' dropout and the IMU's freeze enter the kernel as data
    (Mcu._fault_data): their active periods compiled, the same frames and end state as the
    Python lean loop and the hooked period; and the faults show (so a kernel that ignored
    them would differ)."""
    seen = _count_kernel_periods(monkeypatch)
    got = _drive_with_data_faults()
    assert got[1] & StatusBit.LEFT_ENCODER_FAULT  # the count froze long enough for the bit
    assert got[1] & StatusBit.IMU_FAULT  # and the IMU's sample
    assert seen["kernel"] >= 180 and seen["python"] == 0 and seen["run"] > 150
    monkeypatch.setattr(Mcu, "inject", lambda self, f: f)  # the same drive without the faults
    assert got[0] != _drive_with_data_faults()[0]
    monkeypatch.undo()
    monkeypatch.setattr(LeanLoop, "compiled", False)
    assert got == _drive_with_data_faults()
    monkeypatch.setattr(LeanLoop, "compiled", True)
    monkeypatch.setattr(Mcu, "lean", False)
    assert got == _drive_with_data_faults()


def _drive_with_overcurrent(kind: str = "overcurrent") -> tuple[Any, ...]:
    """A drive through Mcu.advance with a fault of ``kind`` on the right wheel for 0.5 s from
    0.5 s in (over-current latches at once; a blocked wheel draws the stall current and its
    stall latches after stall_time: the driver brakes, the robot faults): frames, end state."""
    p = load_profile()
    rig = TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery), keep=False)
    rig.enable()
    mcu = rig.mcu
    t = mcu.clock.now() - mcu.boot_time
    mcu.inject(Fault(kind, "right", start=t + 0.5, duration=0.5))
    rig.drive(0.5, 0.2, 1.0)
    mcu._lean.release()
    tr = mcu.truth
    return (rig.trace, tr.x, tr.y, tr.yaw, mcu.odometer, mcu.encoder_counts(), mcu.status,
            mcu.motion_fault, int(mcu.state), mcu.motors["right"].status_bits,
            dict(mcu._counters), list(mcu._due))


@pytest.mark.parametrize(("kind", "bit", "flag"), [
    ("overcurrent", StatusBit.RIGHT_OVER_CURRENT, "C_OVER_R"),
    ("stall", StatusBit.RIGHT_MOTOR_STALLED, "C_BLOCK_R")])
def test_overcurrent_and_stall_faults_run_in_the_kernel(
        monkeypatch: pytest.MonkeyPatch, kind: str, bit: int, flag: str) -> None:
    """The injected over-current and the blocked wheel enter the kernel as data
    (Mcu._fault_data: C_OVER_L/R, which the kernel latches; C_BLOCK_L/R): their active periods
    compiled, the same frames and end state as the Python lean loop and the hooked period; the
    fault shows, and a kernel that ignored the flag would differ."""
    seen = _count_kernel_periods(monkeypatch)
    got = _drive_with_overcurrent(kind)
    assert got[6] & bit and got[7] & StatusBit.RIGHT_MOTOR_FAULT  # latched: the robot faulted
    assert got[-3] == (1 if kind == "overcurrent" else 2)  # DriverStatus
    assert seen["kernel"] >= 100 and seen["python"] == 0
    monkeypatch.setattr(Mcu, "inject", lambda self, f: f)  # the same drive without the fault
    assert got[0] != _drive_with_overcurrent(kind)[0]
    monkeypatch.undo()
    monkeypatch.setattr(LeanLoop, "compiled", False)
    assert got == _drive_with_overcurrent(kind)
    monkeypatch.setattr(LeanLoop, "compiled", True)
    monkeypatch.setattr(Mcu, "lean", False)
    assert got == _drive_with_overcurrent(kind)
    monkeypatch.undo()
    set_data = KernelLoop.set_fault_data  # a kernel deaf to the flag: not the hooked trace

    def deaf(self: KernelLoop, data: Any) -> None:
        set_data(self, data)
        self.k[getattr(self.lk, flag)] = 0.0

    monkeypatch.setattr(KernelLoop, "set_fault_data", deaf)
    assert _drive_with_overcurrent(kind) != got


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
def test_bms_polls_run_in_the_kernel_also_when_the_pack_steps_in_the_same_period(
        monkeypatch: pytest.MonkeyPatch, shift: int) -> None:
    seen = _count_kernel_periods(monkeypatch)
    got, _ = _drive_polled(shift)
    assert got[2] & int(StatusBit.CHARGING) and got[1] & int(StatusBit.CHARGING)
    monkeypatch.setattr(Mcu, "lean", False)
    hooked, both = _drive_polled(shift)  # the hooked period, step by step
    assert got == hooked
    # a poll in a period that also steps the pack (shift 19: some are) stays in the kernel:
    # polled after the step, the status word made again
    assert seen["python"] == 0 and (both > 0) == (shift == 19)


def _schedule(rig: TraceRig) -> list[tuple[int, int, bytes]]:
    """1400 periods of frames from the upper side: MotionCommand every 4 periods (repeats,
    changes, Smoothed, a malformed one, a gap beyond the watchdog), Standby and Enable, and a
    LedCommand."""
    codec, out, counter = rig.codec, [], 0

    def frame(k: int, name: str, **values: Any) -> None:
        nonlocal counter
        msg = codec.message(name)
        if msg.has_counter:
            values["Counter"] = counter
            counter = (counter + 1) & 0xF
        out.append((k, msg.frame_id, msg.encode(values)))

    for k in range(0, 1400, 4):
        if 900 <= k < 1100:
            continue  # commands stop: the watchdog brakes
        v = 0.6 if k < 300 else 0.4 if k < 600 else 2.5  # 2.5: SPEED_LIMITED
        frame(k, "MotionCommand", Linear=v, Angular=0.2,
              Mode="Smoothed" if 400 <= k < 500 else "Raw")
        if k == 200:  # one byte short: malformed, COMMAND_REJECTED
            out[-1] = (k, out[-1][1], out[-1][2][:-1])
        if k == 520:
            frame(k, "ControlCommand", Command="Standby")
        if k == 560:
            frame(k + 1, "ControlCommand", Command="EnableCanControl")
        if k == 700:
            frame(k + 2, "LedCommand", Strip=0, Submodule=3, Urgency=0, Abnormal=0, Normal=0xA3,
                  Color=0xFF0000)
    return out


def _drive_scheduled(in_advance: bool) -> tuple[Any, ...]:
    p = load_profile()
    rig = TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery), keep=False)
    rig.enable()
    frames, m = _schedule(rig), rig.mcu
    if in_advance:
        m.advance(700, [f for f in frames if f[0] < 700])
        m.advance(700, [(k - 700, i, d) for k, i, d in frames if k >= 700])
    else:
        for k in range(1400):
            for _, frame_id, data in (f for f in frames if f[0] == k):
                m.receive(frame_id, data)
            m.advance(1)
    m._lean.release()
    tr = m.truth
    return (rig.trace, tr.x, tr.y, tr.yaw, tr.v, m.odometer, m.encoder_counts(), m.status,
            int(m.state), m.imu_sample, m._last_cmd, m._last_cmd_time, m.leds[(0, 3)],
            dict(m.stats), m._bms_charge)


def test_runs_span_repeated_motion_commands(monkeypatch: pytest.MonkeyPatch) -> None:
    runs: list[int] = []
    run = fastbatch.run

    def counted(kl: KernelLoop, n: int, fresh: Any = ()) -> int:
        done = run(kl, n, fresh)
        runs.append(done)
        return done

    monkeypatch.setattr(fastbatch, "run", counted)
    got = _drive_scheduled(True)
    done = [d for d in runs if d]
    assert sum(done) > 1000 and sum(done) / len(done) > 12  # runs span commands
    runs.clear()
    assert got == _drive_scheduled(False)  # receive, then one period, each period
    assert max(runs) == 1
    monkeypatch.setattr(Mcu, "lean", False)
    assert got == _drive_scheduled(True)  # the hooked period


def test_incoming_frames_out_of_the_periods_are_refused() -> None:
    rig = TraceRig(profile=load_profile(), keep=False)
    with pytest.raises(ValueError, match=r"periods 0 \.\. 3"):
        rig.mcu.advance(4, [(4, 0x100, b"")])
    with pytest.raises(ValueError, match="period order"):
        rig.mcu.advance(4, [(2, 0x100, b""), (1, 0x100, b"")])


@pytest.mark.parametrize("runs", [True, False])
def test_a_run_after_a_watchdog_stop_clears_the_watchdog_bit(runs: bool) -> None:
    """The first command after a watchdog stop: the periods of a run report no WATCHDOG_STOP
    (``_target`` clears the flag in each; the run once kept the flag it started with)."""
    rig = TraceRig(profile=load_profile(), keep=False)
    rig.enable()
    rig.drive(0.5, 0.1, 0.5)
    rig.run(1.0)  # commands stop: the watchdog brakes
    assert rig.mcu.status & int(StatusBit.WATCHDOG_STOP)
    rig.send("MotionCommand", Linear=0.3, Angular=0.0, Mode="Raw")
    if runs:
        rig.mcu.advance(8)
    else:
        for _ in range(8):
            rig.step()
    assert not rig.mcu.status & int(StatusBit.WATCHDOG_STOP)
