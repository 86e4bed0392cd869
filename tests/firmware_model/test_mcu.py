"""The emulated MCU, frame for frame, on the simulated clock."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.errors import ConfigError
from lowerbase.firmware_model.faults import parse_fault
from lowerbase.firmware_model.mcu import RobotState
from lowerbase.firmware_model.parameters import SPECS
from lowerbase.firmware_model.profile import Profile, load_profile
from lowerbase.firmware_model.sim import SimRig
from lowerbase.protocol.codec import default_codec
from lowerbase.protocol.status_codes import StatusBit

INDEX = {spec.name: i for i, spec in SPECS.items()}


def ideal_profile() -> Profile:
    """No lag, no ramp, no noise, no geometry error: closed-form answers hold exactly."""
    p = load_profile()
    return p.replace(
        motor=dataclasses.replace(p.motor, time_constant=0.0, max_wheel_accel=0.0),
        imu=dataclasses.replace(p.imu, noise=False),
        truth=dataclasses.replace(p.truth, left_radius_error=0.0, right_radius_error=0.0,
                                  track_error=0.0),
    )


def test_straight_line_gives_exactly_the_predicted_pulses() -> None:
    rig = SimRig(ideal_profile())
    rig.enable()
    v, t = 0.5, 2.0
    rig.drive(v, 0.0, t)
    c = rig.profile.chassis
    expected = math.floor(v * t / c.wheel_perimeter * c.ratio_left * c.pulse_per_circle)
    assert rig.mcu.encoder_counts() == (expected, expected)
    assert rig.mcu.truth.x == pytest.approx(v * t, abs=1e-9)
    assert rig.mcu.truth.y == pytest.approx(0.0, abs=1e-12)
    left, right = (f.values for f in rig.frames("WheelFeedback")[-2:])
    assert (left["Wheel"], right["Wheel"]) == (0, 1)
    assert left["LeftCount"] == right["RightCount"]
    per_cycle = v * 0.02 / c.wheel_perimeter * c.ratio_left * c.pulse_per_circle
    assert expected - per_cycle <= left["LeftCount"] <= expected  # sent within the last cycle


def test_rotation_in_place() -> None:
    rig = SimRig(ideal_profile())
    rig.enable()
    w, t = 0.5, 2.0
    rig.drive(0.0, w, t)
    c = rig.profile.chassis
    rim = w * c.wheel_distant / 2 * t / c.wheel_perimeter * c.ratio_left * c.pulse_per_circle
    assert rig.mcu.encoder_counts() == (math.floor(-rim), math.floor(rim))
    assert rig.mcu.truth.yaw == pytest.approx(w * t, abs=1e-9)
    assert math.hypot(rig.mcu.truth.x, rig.mcu.truth.y) < 1e-9


def test_smoothed_path_respects_the_acceleration_limit() -> None:
    rig = SimRig(ideal_profile())
    rig.enable()
    a = rig.profile.chassis.linear_accel_limit
    rig.drive(1.0, 0.0, 0.5, smoothed=True)
    assert rig.last("MotionState")["Linear"] == pytest.approx(a * 0.5, abs=a * rig.mcu.dt + 2e-3)
    raw = SimRig(ideal_profile())
    raw.enable()
    raw.drive(1.0, 0.0, 0.1)  # the raw path skips the smoother ...
    assert raw.last("MotionState")["Linear"] == pytest.approx(1.0, abs=1e-3)
    raw.drive(9.9 / 3.3, 0.0, 0.1)  # ... but never the hard limits
    assert raw.last("MotionState")["Linear"] <= raw.profile.chassis.max_linear + 1e-3
    assert raw.status() & StatusBit.SPEED_LIMITED


def test_max_rpm_limit_preserves_curvature() -> None:
    p = ideal_profile()
    p = p.replace(chassis=dataclasses.replace(p.chassis, max_rpm=1500.0))
    rig = SimRig(p)
    rig.enable()
    rig.drive(1.0, 0.8, 0.2)
    v, w = rig.last("MotionState")["Linear"], rig.last("MotionState")["Angular"]
    assert w / v == pytest.approx(0.8, rel=5e-3)
    top = 1500.0 / p.chassis.ratio_left / 60 * p.chassis.wheel_perimeter
    assert v + w * p.chassis.wheel_distant / 2 == pytest.approx(top, rel=5e-3)


def test_watchdog_brakes_when_commands_stop() -> None:
    rig = SimRig()
    rig.enable()
    rig.drive(0.5, 0.0, 2.0)
    t_last = rig.now - 0.02
    timeout = rig.profile.chassis.command_timeout
    rig.run(timeout - 0.1)
    assert not rig.status() & StatusBit.WATCHDOG_STOP
    assert rig.last("MotionState")["Linear"] > 0.45
    rig.run(0.25)
    assert rig.status() & StatusBit.WATCHDOG_STOP
    assert rig.last("SystemStatus")["WatchdogStop"] == 1
    rig.run(0.6)
    assert rig.last("MotionState")["Linear"] == 0.0
    stopped = next(f.t for f in rig.frames("MotionState", since=t_last)
                   if f.values["Linear"] == 0.0)
    assert stopped - t_last < timeout + 0.6  # stopped within 0.6 s of the deadline
    rig.drive(0.2, 0.0, 0.2)  # the next valid command clears it and drives again
    assert not rig.status() & StatusBit.WATCHDOG_STOP
    assert rig.last("MotionState")["Linear"] > 0.1


def test_standby_after_boot_until_enabled() -> None:
    rig = SimRig()
    rig.run(0.1)
    assert rig.mcu.state == RobotState.BOOT
    rig.run(0.4)
    assert rig.last("SystemStatus")["RobotState"] == RobotState.STANDBY
    rig.drive(0.5, 0.0, 0.5)
    assert rig.mcu.encoder_counts() == (0, 0)
    assert rig.status() & StatusBit.COMMAND_IN_STANDBY
    rig.send("ControlCommand", Command="EnableCanControl")
    rig.drive(0.5, 0.0, 0.5)
    assert rig.last("SystemStatus")["RobotState"] == RobotState.ACTIVE
    assert rig.last("SystemStatus")["ControlMode"] == 1
    assert min(rig.mcu.encoder_counts()) > 0
    rig.send("ControlCommand", Command="Standby")
    rig.drive(0.5, 0.0, 1.0)
    assert rig.last("MotionState")["Linear"] == 0.0


def test_estop_latches_until_released_and_reenabled() -> None:
    rig = SimRig()
    rig.enable()
    rig.drive(0.5, 0.0, 1.0)
    rig.send("ControlCommand", Command="EStopSet")
    rig.drive(0.5, 0.0, 1.0)
    assert rig.last("MotionState")["Linear"] == 0.0
    assert rig.status() & StatusBit.ESTOP_COMMAND
    assert rig.last("SystemStatus")["RobotState"] == RobotState.EMERGENCY_STOP
    rig.send("ControlCommand", Command="EnableCanControl")  # no way around the latch
    rig.drive(0.5, 0.0, 0.5)
    assert rig.last("MotionState")["Linear"] == 0.0
    rig.send("ControlCommand", Command="EStopRelease")
    rig.drive(0.5, 0.0, 0.5)
    assert rig.last("SystemStatus")["RobotState"] == RobotState.STANDBY
    assert rig.last("MotionState")["Linear"] == 0.0
    rig.send("ControlCommand", Command="EnableCanControl")
    rig.drive(0.5, 0.0, 0.5)
    assert rig.last("MotionState")["Linear"] > 0.3


def test_estop_button_fault() -> None:
    rig = SimRig(faults=["estop@1+1"])
    rig.enable()
    rig.drive(0.3, 0.0, 1.5)
    assert rig.status() & StatusBit.ESTOP_BUTTON
    assert rig.last("MotionState")["Linear"] == 0.0
    rig.drive(0.3, 0.0, 1.0)  # the button is up again but the stop stays latched
    assert rig.status() & StatusBit.ESTOP_COMMAND
    rig.send("ControlCommand", Command="EStopRelease")
    rig.send("ControlCommand", Command="EnableCanControl")
    rig.drive(0.3, 0.0, 0.5)
    assert rig.last("MotionState")["Linear"] > 0.2


def test_nan_and_out_of_range_commands_are_rejected_and_flagged() -> None:
    rig = SimRig()
    rig.enable()
    rig.drive(0.3, 0.0, 0.5)
    assert not rig.mcu.command(math.nan, 0.0)
    assert rig.mcu.stats["rx_motion_rejected"] == 1
    msg = default_codec().message("MotionCommand")
    bad = (5000).to_bytes(2, "little", signed=True) + bytes(4)  # 5 m/s: outside the catalog
    rig.mcu.receive(msg.frame_id, bad)
    rig.mcu.receive(msg.frame_id, b"\x00")  # wrong length
    rig.run(0.2)
    assert rig.mcu.stats["rx_malformed"] == 2
    assert rig.status() & StatusBit.COMMAND_REJECTED
    rig.send("ControlCommand", Command="FaultClear")
    rig.run(0.2)
    assert not rig.status() & StatusBit.COMMAND_REJECTED


def test_unknown_ids_and_garbage_are_counted_not_fatal() -> None:
    rig = SimRig()
    rig.enable()
    rig.mcu.receive(0x7AB, b"\x01\x02")
    rig.mcu.receive(default_codec().message("Heartbeat").frame_id, bytes(8))  # a lower frame
    rig.run(0.1)
    assert rig.mcu.stats["rx_unknown_id"] == 1
    assert rig.mcu.stats["rx_ignored"] == 1


def test_every_periodic_frame_at_its_rate() -> None:
    p = load_profile()
    rig = SimRig(p, bms=McuBmsAdapter.from_battery_table(p.battery))
    rig.run(10.0)
    codec = default_codec()
    per_cycle = {"WheelFeedback": 2, "LedState": 16}
    for msg in codec:
        if not msg.is_periodic or "Lower" not in msg.senders:
            continue
        frames = rig.frames(msg.name)
        n = per_cycle.get(msg.name, 1)
        assert msg.cycle_time is not None
        assert len(frames) == pytest.approx(10.0 / msg.cycle_time * n, abs=n), msg.name
        times = sorted({f.t for f in frames})
        gaps = {round(b - a, 6) for a, b in itertools.pairwise(times)}
        assert gaps == {msg.cycle_time}, msg.name
        counters = [f.values["Counter"] for f in frames] if msg.has_counter else []
        if msg.name == "WheelFeedback":  # both wheels of a cycle share the counter
            assert counters[0::2] == counters[1::2]
            counters = counters[0::2]
        assert all((b - a) % 16 == 1 for a, b in itertools.pairwise(counters))


def test_version_strings_over_multiframe_sequences() -> None:
    rig = SimRig()
    rig.run(0.4)
    rig.send("VersionRequest", Field="All")
    texts: dict[int, bytes] = {}
    for f in rig.frames("VersionResponse"):
        v = f.values
        assert v["Sequence"] == len(texts.get(v["Field"], b"")) // 6
        texts[v["Field"]] = texts.get(v["Field"], b"") + v["Text"].to_bytes(6, "little")
    ident = rig.profile.identity
    assert {k: t.rstrip(b"\0").decode() for k, t in texts.items()} == {
        1: ident.hardware_version, 2: ident.software_version,
        3: ident.iap_software_version, 4: ident.movebase_type}
    lasts = [f.values["Last"] for f in rig.frames("VersionResponse")]
    assert sum(lasts) == 4


def _param(rig: SimRig, name: str, value: float | None = None) -> dict[str, object]:
    before = len(rig.frames("ParameterResponse"))
    rig.send("ParameterRequest", Index=INDEX[name], Op=0 if value is None else 1,
             Value=0.0 if value is None else value)
    after = rig.frames("ParameterResponse")
    assert len(after) == before + 1
    return after[-1].values



def test_a_repeated_command_is_limited_by_the_parameters_in_force() -> None:
    """Mcu._motion keeps the last limit_twist result for a repeated command: a parameter
    written between two equal commands still takes effect, and -0.0/0.0 keep their sign."""
    rig = SimRig()
    rig.enable()
    rig.drive(1.1, 0.3, 0.1)
    assert rig.mcu._last_cmd == (1.1, 0.3, 0)
    assert _param(rig, "maxLinear", 0.8)["Result"] == 0
    rig.drive(1.1, 0.3, 0.1)
    assert rig.mcu._last_cmd is not None and rig.mcu._last_cmd[0] == pytest.approx(0.8)
    rig.mcu.command(0.5, -0.0)
    rig.mcu.command(0.5, 0.0)
    assert math.copysign(1.0, rig.mcu._last_cmd[1]) == 1.0


def test_parameters_read_write_nack_and_persist(tmp_path: Path) -> None:
    path = tmp_path / "params.json"
    rig = SimRig(params_path=path)
    rig.run(0.4)
    assert _param(rig, "wheelPerimeter")["Value"] == pytest.approx(0.6283, rel=1e-6)
    nack = _param(rig, "maxLinear", 50.0)
    assert nack["Result"] == 2  # OutOfRange
    assert nack["Value"] == pytest.approx(1.2)
    unknown = dict(rig.frames("ParameterResponse")[-1].values)
    rig.send("ParameterRequest", Index=200, Op=0, Value=0.0)
    unknown = rig.frames("ParameterResponse")[-1].values
    assert unknown["Result"] == 1  # UnknownIndex
    assert _param(rig, "pulsePerCircle", 4096.5)["Result"] == 6  # InvalidValue: not an integer
    ack = _param(rig, "maxLinear", 0.8)
    assert (ack["Result"], ack["Value"]) == (0, pytest.approx(0.8))
    assert json.loads(path.read_text())["parameters"]["maxLinear"] == pytest.approx(0.8)
    # live: the new limit applies at once
    rig.send("ControlCommand", Command="EnableCanControl")
    rig.drive(1.2, 0.0, 0.5)
    assert rig.last("MotionState")["Linear"] == pytest.approx(0.8, abs=5e-3)
    # geometry cannot change while the wheels turn
    assert _param(rig, "wheelDistant", 0.6)["Result"] == 4
    boots = rig.mcu.boot_counter
    restarted = SimRig(params_path=path)
    restarted.run(0.4)
    assert _param(restarted, "maxLinear")["Value"] == pytest.approx(0.8)
    assert restarted.mcu.boot_counter == boots + 1
    restarted.run(0.5)
    assert restarted.last("Heartbeat")["BootCounter"] == boots + 1


def test_a_crash_mid_write_leaves_the_previous_file(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "params.json"
    rig = SimRig(params_path=path)
    rig.run(0.4)
    assert _param(rig, "maxAngular", 0.7)["Result"] == 0
    before = path.read_bytes()

    def crash(*_: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", crash)
    result = _param(rig, "maxAngular", 0.9)
    assert result["Result"] == 5  # StorageError
    assert result["Value"] == pytest.approx(0.7)  # the value in force is the persisted one
    assert path.read_bytes() == before
    assert not [p for p in tmp_path.iterdir() if p.name != "params.json"]  # no temp left
    rig.run(0.2)
    assert rig.status() & StatusBit.PARAMETER_STORE_FAILED


def test_corrupt_parameter_file_boots_on_defaults_and_says_so(tmp_path: Path) -> None:
    path = tmp_path / "params.json"
    path.write_text('{"parameters": {"maxLinear": 99, "bogus": 1}')  # truncated JSON
    rig = SimRig(params_path=path)
    rig.run(0.5)
    assert rig.status() & StatusBit.PARAMETER_ERROR
    assert _param(rig, "maxLinear")["Value"] == pytest.approx(1.2)


def test_reboot_command_and_odometer(tmp_path: Path) -> None:
    rig = SimRig(params_path=tmp_path / "p.json")
    rig.enable()
    rig.drive(0.5, 0.0, 2.0)
    rig.run(1.5)  # the watchdog stops it; the odometer frame then holds the final distance
    # encoders with nominal parameters vs the truth (right wheel 0.3 % larger by default)
    assert rig.last("Odometer")["Distance"] == pytest.approx(rig.mcu.truth.distance, rel=0.005)
    boots = rig.mcu.boot_counter
    rig.send("ControlCommand", Command="Reboot")
    rig.run(0.6)
    assert rig.last("Heartbeat")["BootCounter"] == boots + 1
    assert rig.last("Heartbeat")["Uptime"] < 0.6
    assert rig.last("SystemStatus")["RobotState"] == RobotState.STANDBY
    assert rig.last("Odometer")["Distance"] > 0.9  # persisted across the reboot
    rig.send("ControlCommand", Command="OdometerReset")
    rig.run(0.2)
    assert rig.last("Odometer")["Distance"] == 0.0


def test_stall_fault_latches_until_cleared_when_gone() -> None:
    rig = SimRig(faults=["stall:left@1+2"])
    rig.enable()
    rig.drive(0.4, 0.0, 1.0)
    rig.drive(0.4, 0.0, 1.0)
    code = rig.status()
    assert code & StatusBit.LEFT_MOTOR_FAULT
    assert code & (StatusBit.LEFT_MOTOR_STALLED | StatusBit.LEFT_OVER_CURRENT)
    assert rig.last("SystemStatus")["RobotState"] == RobotState.FAULT
    rig.send("ControlCommand", Command="FaultClear")  # the wheel is still blocked
    rig.run(0.2)
    assert rig.status() & StatusBit.LEFT_MOTOR_FAULT
    rig.run(1.0)  # the fault ends at t = 3 s
    rig.send("ControlCommand", Command="FaultClear")
    rig.run(0.2)
    assert not rig.status() & StatusBit.LEFT_MOTOR_FAULT
    rig.send("ControlCommand", Command="EnableCanControl")
    rig.drive(0.4, 0.0, 0.5)
    assert rig.last("MotionState")["Linear"] > 0.3


def test_encoder_dropout_and_imu_freeze_show_in_status() -> None:
    rig = SimRig(faults=["encoder:right@1", "imu-freeze@1"])
    rig.enable()
    rig.drive(0.4, 0.0, 2.0)
    code = rig.status()
    assert code & StatusBit.RIGHT_ENCODER_FAULT
    assert code & StatusBit.IMU_FAULT
    wf = [f.values for f in rig.frames("WheelFeedback", since=rig.now - 0.1)]
    right = [v for v in wf if v["Wheel"] == 1]
    assert right and all(v["RightDriverStatus"] & 0b100 for v in right)
    assert len({v["RightCount"] for v in right}) == 1  # frozen


def test_output_faults_drop_delay_corrupt_silence() -> None:
    silent = SimRig(faults=["silence@1+1"])
    silent.run(3.0)
    assert not [f for f in silent.sent if 1.0 <= f.t < 2.0]
    assert [f for f in silent.sent if f.t >= 2.0]
    delayed = SimRig(faults=["delay:0.05"])
    delayed.run(1.0)
    hb = delayed.frames("Heartbeat")[1]  # [0] is the boot-up Heartbeat at t = 0 (+ delay)
    assert hb.t == pytest.approx(0.5 + 0.05, abs=delayed.mcu.dt)
    lossy = SimRig(faults=["drop:1"])
    lossy.run(1.0)
    assert lossy.sent == []
    corrupt = SimRig(faults=["corrupt:1"])
    corrupt.keep = False
    sizes = []
    corrupt.mcu._send = lambda fid, data: sizes.append(
        len(data) == default_codec().message(fid).length)
    corrupt.run(0.5)
    assert sizes and not any(sizes)


def test_fault_specs_are_validated() -> None:
    assert str(parse_fault("stall:left@5+2")) == "stall:left@5+2"
    for bad in ("stall", "stall:middle", "drop:2", "delay:-1", "warp", "imu-freeze:3"):
        with pytest.raises(ConfigError):
            parse_fault(bad)


def test_imu_frames_exact_without_noise() -> None:
    rig = SimRig(ideal_profile())
    rig.enable()
    rig.drive(0.0, 0.5, 1.0)
    gyro = rig.last("ImuGyro")
    accel = rig.last("ImuAccel")
    assert gyro["Z"] == pytest.approx(0.5, abs=1e-4)
    assert accel["Z"] == pytest.approx(rig.profile.imu.gravity, abs=1e-3)


def test_led_commands_show_in_led_state() -> None:
    rig = SimRig()
    rig.run(0.4)
    rig.send("LedCommand", Strip="Shelf", Submodule="All", Urgency=0, Abnormal=0xFF,
             Normal=0, Color=0xFF0000)
    rig.send("LedCommand", Strip="Body", Submodule=3, Urgency=0, Abnormal=0, Normal=0x80,
             Color=0x00FF00)
    rig.send("LedCommand", Strip="Body", Submodule=4, Urgency=0x12, Abnormal=0, Normal=0x80,
             Color=0x0000FF)  # urgency must be 0x00 or 0xFF: ignored
    rig.send("LedCommand", Strip="Body", Submodule=5, Urgency=0, Abnormal=0, Normal=0x77,
             Color=0x0000FF)  # not a code of the seed's table: ignored
    rig.run(1.1)
    shown = {(f.values["Strip"], f.values["Submodule"]): f.values
             for f in rig.frames("LedState", since=rig.now - 1.0)}
    assert len(shown) == 16
    assert all(shown[(1, sub)]["Color"] == 0xFF0000 and shown[(1, sub)]["Abnormal"] == 0xFF
               for sub in range(1, 9))
    assert shown[(0, 3)]["Normal"] == 0x80 and shown[(0, 3)]["Color"] == 0x00FF00
    assert shown[(0, 4)]["Normal"] == 0xA3 and shown[(0, 5)]["Normal"] == 0xA3  # unchanged
    assert rig.mcu.stats["rx_led_invalid"] == 2


_IDS = [m.frame_id for m in default_codec()]


@settings(max_examples=300, deadline=None)
@given(frames=st.lists(st.tuples(st.one_of(st.sampled_from(_IDS), st.integers(0, 0x7FF)),
                                 st.binary(max_size=8)), max_size=20))
def test_fuzz_random_frames_never_crash_the_mcu(frames: list[tuple[int, bytes]]) -> None:
    rig = SimRig()
    rig.run(0.35)
    for frame_id, data in frames:
        rig.mcu.receive(frame_id, data)
        rig.step()
    rig.run(0.1)
    assert rig.mcu.stats["rx_frames"] == len(frames)
