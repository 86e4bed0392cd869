"""The emulator's frame trace is pinned: same seed, same frames, bit for bit.

A standard drive (boot, raw and smoothed driving, LEDs, parameters, version strings, a rejected
command, the watchdog, and every fault kind including the conformance defects, a FaultClear
and a reboot) is recorded as every frame's (simulated time, id, bytes) plus the ground truth
at the end of each segment. The SHA-256 of each segment was recorded with the emulator as it
was before the speed work of issue 10 (the general control loop, one method call per
concern); any change of behaviour, however small, changes a hash. The lean loop used when no
fault or defect acts (compiled where numba is there) must give exactly the trace of the
period with its fault hooks checked.

The hashes depend on IEEE doubles and numpy's PCG64 streams, which are the same on every
platform CPython and numpy support; a different libm could in principle change a last bit of
sin/cos/expm1 (it has not on x86_64 glibc, where they were recorded).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Callable
from typing import Any

import pytest

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.firmware_model.fastkernel import KernelLoop, kernel
from lowerbase.firmware_model.fastloop import LeanLoop
from lowerbase.firmware_model.mcu import Command, Mcu
from lowerbase.firmware_model.profile import Profile, load_profile
from lowerbase.firmware_model.sim import SimRig
from lowerbase.protocol.status_codes import StatusBit

#: segment name -> (frames, sha256 of frames + truth) recorded before the speed work
EXPECTED: dict[str, tuple[int, str]] = {
    "boot_and_drive":
        (3544, "586d5b1b871dcd00479a174b8a117827e39f0a1ae3e7007a4d1d91a02fbb9320"),
    "requests":
        (1147, "052c5575df756c26fd86498821078f350658828a8bc4b1a6c62867eab4710c90"),
    "bus_faults":
        (1057, "aaf6e9726043141547122baa05995e4f29384ac746a20d29cbb50f586cf97a02"),
    "motion_faults":
        (1459, "9cede447df5b78e36685b02ffe8f100ba0a7ac05f06efb6e743524dfafcb17c7"),
    "sensor_faults":
        (3105, "d326de852506cd73b108934b18b8ee123ab27151e6dfdbae5478f601822aa145"),
    "estop_and_defects":
        (2645, "d9a83700d9c3c1ec348ca07da11084090451547471bceb6ebf9f451af5561ea1"),
    "reboot":
        (1180, "7709502a877f816479ec217b2d4c782e8d2b225536111c152f4cd7493a1d5837"),
    "ideal/boot_and_drive":
        (3504, "bf0da19cfa8367803b4433181209ae790bc2021538378c3d74976262ef61b6f3"),
    "ideal/reboot":
        (1170, "b35fa2c285a9fa272c1a1bc631d8b83186cc12155850fc7fb8de65fdf1089005"),
}


class TraceRig(SimRig):
    """A SimRig that keeps every frame as (t, id, data), nothing decoded."""

    def __init__(self, **kwargs: Any) -> None:
        self.trace: list[tuple[float, int, bytes]] = []
        super().__init__(**kwargs)

    def _on_send(self, frame_id: int, data: bytes) -> None:
        self.trace.append((self.clock.now(), frame_id, data))


def _digest(rig: TraceRig, start: int) -> tuple[int, str]:
    h = hashlib.sha256()
    for t, frame_id, data in rig.trace[start:]:
        h.update(f"{t!r} {frame_id} {data.hex()}\n".encode())
    tr, m = rig.mcu.truth, rig.mcu
    h.update(repr((tr.x, tr.y, tr.yaw, tr.v, tr.w, tr.distance, m.odometer,
                   m.encoder_counts(), m.status, int(m.state))).encode())
    return len(rig.trace) - start, h.hexdigest()


def _segments() -> list[tuple[str, Callable[[TraceRig], None]]]:
    def boot_and_drive(r: TraceRig) -> None:
        r.enable()
        r.drive(0.6, 0.2, 3.0)
        r.drive(-0.4, -0.5, 2.0, smoothed=True)
        r.drive(0.8, 0.0, 1.5, smoothed=True)
        r.drive(2.5, 0.0, 0.3)  # beyond maxLinear: SPEED_LIMITED
        r.run(1.2)  # the watchdog ends it (the flag stays, the command is gone)
        r.drive(0.0, 0.0, 0.5)

    def requests(r: TraceRig) -> None:
        r.send("LedCommand", Strip=1, Submodule=0, Urgency=0xFF, Abnormal=0, Normal=0xA3,
               Color=0x00FF00)
        r.send("ParameterRequest", Index=1, Op=0, Value=0.0)
        r.send("VersionRequest", Field=0)
        r.mcu.command(math.nan, 0.0)  # rejected
        r.mcu.receive(r.codec.message("MotionCommand").frame_id, b"\x01\x02")  # malformed
        r.run(0.3)
        r.send("ControlCommand", Command="FaultClear")
        r.drive(0.3, 0.0, 1.0)
        r.run(1.5)  # the watchdog brakes

    def bus_faults(r: TraceRig) -> None:
        r.mcu.inject("drop:0.2@0+1")  # relative to boot: started now by inject(start 0)
        r.drive(0.5, 0.1, 1.2)
        r.mcu.inject("corrupt:0.3")
        r.drive(0.5, 0.1, 0.6)
        r.mcu.clear_fault("corrupt")
        r.mcu.inject("delay:0.03")
        r.drive(0.5, 0.1, 0.6)
        r.mcu.clear_fault("delay")
        r.mcu.inject("silence")
        r.drive(0.5, 0.1, 0.4)
        r.mcu.clear_fault()
        r.drive(0.5, 0.1, 0.4)

    def motion_faults(r: TraceRig) -> None:
        r.mcu.inject("stall:left")
        r.drive(0.5, 0.0, 1.5)
        r.mcu.clear_fault("stall")
        r.send("ControlCommand", Command="FaultClear")
        r.run(0.1)
        r.send("ControlCommand", Command="EnableCanControl")
        r.drive(0.5, 0.0, 0.5)
        r.mcu.inject("encoder:right")
        r.drive(0.5, 0.0, 0.6)
        r.mcu.clear_fault("encoder")
        r.mcu.inject("overcurrent:right")
        r.drive(0.5, 0.0, 0.3)
        r.mcu.clear_fault()
        r.send("ControlCommand", Command="FaultClear")
        r.run(0.1)
        r.send("ControlCommand", Command="EnableCanControl")
        r.drive(0.4, -0.3, 0.5)

    def sensor_faults(r: TraceRig) -> None:
        r.mcu.inject("imu-bias:0.05")
        r.drive(0.4, 0.3, 0.7)
        r.mcu.inject("imu-freeze")
        r.drive(0.4, 0.3, 0.5)
        r.mcu.clear_fault()
        r.drive(0.4, 0.3, 0.3)
        r.mcu.bms.connect_charger()
        r.run(1.2)
        r.mcu.bms.disconnect_charger()
        r.mcu.inject("bms-silence")
        r.drive(0.2, 0.0, 4.0)
        r.mcu.clear_fault()
        r.drive(0.2, 0.0, 1.0)

    def estop_and_defects(r: TraceRig) -> None:
        r.mcu.inject("estop")
        r.drive(0.3, 0.0, 0.4)
        r.mcu.clear_fault()
        r.send("ControlCommand", Command="EStopRelease")
        r.run(0.1)
        r.send("ControlCommand", Command="EnableCanControl")
        r.mcu.control(Command.ESTOP_SET)
        r.run(0.2)
        r.send("ControlCommand", Command="EStopRelease")
        r.send("ControlCommand", Command="EnableCanControl")
        for defect in ("counter-stuck", "slow-heartbeat", "no-watchdog"):
            r.mcu.inject(f"defect:{defect}")
            r.drive(0.3, 0.1, 0.6)
            r.run(1.2)
            r.mcu.clear_fault()
        r.run(0.5)

    def reboot(r: TraceRig) -> None:
        r.send("ControlCommand", Command="Reboot")
        r.enable()
        r.drive(0.7, -0.2, 2.0)
        r.send("ControlCommand", Command="OdometerReset")
        r.drive(0.7, 0.4, 1.0, smoothed=True)

    return [("boot_and_drive", boot_and_drive), ("requests", requests),
            ("bus_faults", bus_faults), ("motion_faults", motion_faults),
            ("sensor_faults", sensor_faults), ("estop_and_defects", estop_and_defects),
            ("reboot", reboot)]


def ideal_profile() -> Profile:
    """No motor lag or ramp, no IMU noise: the other branches of the models."""
    p = load_profile()
    return p.replace(motor=dataclasses.replace(p.motor, time_constant=0.0, max_wheel_accel=0.0),
                     imu=dataclasses.replace(p.imu, noise=False))


def record() -> dict[str, tuple[int, str]]:
    """Run the standard drive (default profile with its BMS), then the first and last
    segments on the ideal profile without a BMS; segment name -> (frames, digest)."""
    out = {}
    p = load_profile()
    runs = [("", TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery),
                          keep=False), _segments()),
            ("ideal/", TraceRig(profile=ideal_profile(), keep=False),
             [_segments()[0], _segments()[-1]])]
    for prefix, rig, segments in runs:
        for name, segment in segments:
            start = len(rig.trace)
            segment(rig)
            out[prefix + name] = _digest(rig, start)
    return out


def test_the_frame_trace_is_what_it_was() -> None:
    got = record()
    assert list(got) == list(EXPECTED)
    for name in EXPECTED:
        assert got[name] == EXPECTED[name], name


def test_the_fault_hooks_in_every_period_give_the_same_trace(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """With the fault hooks checked in every period (never the compiled or hook-free one),
    the same frames, bit for bit."""
    monkeypatch.setattr(Mcu, "lean", False)
    assert record() == EXPECTED


def test_the_hooks_are_checked_only_while_a_fault_acts(monkeypatch: pytest.MonkeyPatch) -> None:
    """The periods without the fault hooks are every period but those with a fault acting that
    is not always data (a gyro bias, added and taken back before its periods, is)."""
    calls: list[None] = []
    monkeypatch.setattr(LeanLoop, "compiled", False)  # runs of compiled periods skip step()
    lean_step = LeanLoop.step

    def step(self: LeanLoop, hooks: bool = False, kernel: bool = True) -> None:
        if not hooks:
            calls.append(None)
        lean_step(self, hooks, kernel)

    monkeypatch.setattr(LeanLoop, "step", step)
    rig = TraceRig(profile=load_profile(), keep=False)
    rig.enable()
    rig.drive(0.5, 0.1, 1.0)
    assert len(calls) == round(rig.now / rig.mcu.dt)  # every step
    rig.mcu.inject("drop:0.5@100")  # armed for later: nothing changes yet, no hooks
    rig.drive(0.5, 0.1, 1.0)
    assert len(calls) == round(rig.now / rig.mcu.dt)
    rig.mcu.inject("drop:0.5")  # active now: the hooks
    rig.drive(0.5, 0.1, 1.0)
    assert len(calls) == round((rig.now - 1.0) / rig.mcu.dt)
    rig.mcu.clear_fault()
    rig.drive(0.5, 0.1, 1.0)
    assert len(calls) == round((rig.now - 1.0) / rig.mcu.dt)
    rig.mcu.inject("imu-bias:0.05")
    rig.drive(0.5, 0.1, 1.0)
    rig.mcu.clear_fault()
    rig.drive(0.5, 0.1, 1.0)
    assert len(calls) == round((rig.now - 1.0) / rig.mcu.dt)
    assert rig.mcu._imu_bias_applied == 0.0  # added, then taken back


#: a fault of every kind the compiled period takes as data with the hooks (the frame trace's
#: drive pins what each does, compiled and in Python)
HOOKED = ["silence", "drop:0.5", "corrupt:0.5", "delay:0.03", "bms-silence",
          "defect:slow-heartbeat", "defect:counter-stuck", "defect:no-watchdog", "estop"]


def test_every_fault_is_data_of_the_compiled_period(monkeypatch: pytest.MonkeyPatch) -> None:
    """While any fault acts, the periods are the kernel's as without one: the Python period
    runs only where it runs without faults (the BMS poll in a period that steps the pack)."""
    if kernel() is None:
        pytest.skip("numba is not available: no compiled period")
    seen: list[tuple[bool, bool]] = []
    real = KernelLoop.step

    def step(self: KernelLoop, hooks: bool = False) -> bool:
        done = real(self, hooks)
        seen.append((hooks, done))
        return done

    monkeypatch.setattr(KernelLoop, "step", step)
    p = load_profile()
    rig = TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery), keep=False)
    rig.enable()
    periods = round(1.0 / rig.mcu.dt)
    rig.drive(0.5, 0.1, 1.0)
    seen.clear()
    rig.mcu.inject("encoder:left")  # data of every period, no hooks: period by period
    rig.drive(0.5, 0.1, 1.0)
    assert len(seen) == periods and not any(hooks for hooks, _ in seen)
    python = sum(not done for _, done in seen)
    assert python < periods // 20
    rig.mcu.clear_fault()
    for spec in ["imu-bias:0.05", *HOOKED]:
        rig.drive(0.5, 0.1, 1.0)
        seen.clear()
        rig.mcu.inject(spec)
        rig.drive(0.5, 0.1, 1.0)
        assert len(seen) == periods, spec
        assert all(hooks for hooks, _ in seen) == (spec != "imu-bias:0.05"), spec
        assert sum(not done for _, done in seen) == python, spec
        rig.mcu.clear_fault()
    stats = rig.mcu.stats
    assert stats["tx_silenced"] and stats["tx_dropped"] and stats["tx_corrupted"]
    assert rig.mcu.status & StatusBit.ESTOP_BUTTON and rig.mcu.estop_command


def test_the_trace_covers_every_kind_of_frame() -> None:
    """Not a trace of nothing: every frame the lower computer sends appears."""
    p = load_profile()
    rig = TraceRig(profile=p, bms=McuBmsAdapter.from_battery_table(p.battery), keep=False)
    for _, segment in _segments():
        segment(rig)
    sent = {frame_id for _, frame_id, _ in rig.trace}
    lower = {m.frame_id for m in rig.codec if "Lower" in m.senders}
    assert lower <= sent
    assert rig.mcu.stats["tx_dropped"] > 0 and rig.mcu.stats["tx_corrupted"] > 0
    assert rig.mcu.stats["tx_silenced"] > 0
    status = rig.codec.message("StatusCode")
    seen = 0
    for _, frame_id, data in rig.trace:
        if frame_id == status.frame_id and len(data) == status.length:
            seen |= int(status.decode(data)["Code"])
    for bit in ("ESTOP_BUTTON", "ESTOP_COMMAND", "WATCHDOG_STOP", "COMMAND_REJECTED",
                "COMMAND_IN_STANDBY", "LEFT_MOTOR_FAULT", "RIGHT_OVER_CURRENT",
                "LEFT_MOTOR_STALLED", "RIGHT_ENCODER_FAULT", "IMU_FAULT", "BMS_LINK_LOST",
                "BUS_ERROR", "SPEED_LIMITED", "CHARGING"):
        assert seen & StatusBit[bit], bit


if __name__ == "__main__":  # print the table to pin (after a deliberate behaviour change)
    for name, (n, digest) in record().items():
        print(f'    "{name}": ({n}, "{digest}"),')
