"""Parameters are what the firmware believes; the hardware is the profile's and never changes.

A written ratio or pulsePerCircle changes how the firmware converts commanded speeds into
motor speeds and encoder pulses into reported speeds, never the gearbox or the encoder.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from lowerbase.firmware_model.mcu import Command
from lowerbase.firmware_model.parameters import BY_NAME, Result
from lowerbase.firmware_model.profile import Profile, load_profile
from lowerbase.firmware_model.sim import SimRig


def ideal_profile() -> Profile:
    """No lag, no ramp, no noise, no geometry error."""
    p = load_profile()
    return p.replace(
        motor=dataclasses.replace(p.motor, time_constant=0.0, max_wheel_accel=0.0),
        imu=dataclasses.replace(p.imu, noise=False),
        truth=dataclasses.replace(p.truth, left_radius_error=0.0, right_radius_error=0.0,
                                  track_error=0.0),
    )


def _write(rig: SimRig, name: str, value: float) -> None:
    result, _ = rig.mcu.parameter(BY_NAME[name].index, value)
    assert result == Result.ACK


def test_wrong_ratio_belief_curves_the_real_robot_by_the_closed_form_amount() -> None:
    rig = SimRig(ideal_profile())
    rig.enable()
    _write(rig, "ratioLeft", 30.0)  # the gearbox is 20:1
    v, t = 0.5, 2.0
    rig.drive(v, 0.0, t)
    c = rig.profile.chassis
    # the firmware turns the left motor 30/20 too fast for the real gearbox: left rim 1.5 v
    v_left, v_right = v * 30.0 / 20.0, v
    assert rig.mcu.truth.v == pytest.approx(0.5 * (v_left + v_right), rel=1e-9)
    assert rig.mcu.truth.w == pytest.approx((v_right - v_left) / c.wheel_distant, rel=1e-9)
    assert rig.mcu.truth.yaw == pytest.approx((v_right - v_left) / c.wheel_distant * t, rel=1e-6)
    # ... while what it reports (its beliefs applied to the real encoders) is straight
    assert rig.mcu.wheel_velocity("left") == pytest.approx(v, rel=1e-9)
    assert rig.last("MotionState")["Linear"] == pytest.approx(v, abs=1e-3)
    assert rig.last("MotionState")["Angular"] == pytest.approx(0.0, abs=1e-3)
    # the real encoder counts real motor turns: 1.5x as many on the left
    left, right = rig.mcu.encoder_counts()
    assert left == pytest.approx(1.5 * right, rel=1e-4)


def test_wrong_pulse_per_circle_belief_scales_the_reported_velocity_not_the_count() -> None:
    rig = SimRig(ideal_profile())
    rig.enable()
    _write(rig, "pulsePerCircle", 5000)  # the encoder has 10000 lines per motor turn
    v, t = 0.3, 2.0
    rig.drive(v, 0.0, t)
    c = rig.profile.chassis
    real = math.floor(v * t / c.wheel_perimeter * c.ratio_left * c.pulse_per_circle)
    assert rig.mcu.encoder_counts() == (real, real)  # the real encoder, unchanged
    assert rig.mcu.truth.v == pytest.approx(v, rel=1e-9)  # the robot drives as commanded
    assert rig.mcu.wheel_velocity("left") == pytest.approx(2.0 * v, rel=1e-9)
    assert rig.last("MotionState")["Linear"] == pytest.approx(2.0 * v, abs=1e-3)
    assert rig.mcu.odometer == pytest.approx(2.0 * v * t, rel=1e-3)


def test_wheel_perimeter_belief_moves_the_robot_by_the_ratio_of_the_sizes() -> None:
    rig = SimRig(ideal_profile())
    rig.enable()
    c = rig.profile.chassis
    _write(rig, "wheelPerimeter", c.wheel_perimeter * 1.1)  # believes a 10 % larger wheel
    v, t = 0.4, 2.0
    rig.drive(v, 0.0, t)
    assert rig.mcu.truth.v == pytest.approx(v / 1.1, rel=1e-9)
    assert rig.last("MotionState")["Linear"] == pytest.approx(v, abs=1e-3)


def test_beliefs_from_the_parameter_file_leave_the_hardware_alone(tmp_path: Path) -> None:
    rig = SimRig(ideal_profile(), params_path=tmp_path / "params.json")
    rig.enable()
    _write(rig, "ratioRight", 10.0)
    _write(rig, "pulsePerCircle", 2500)
    rig.mcu.control(Command.REBOOT)  # the boot loads the beliefs from the file
    assert rig.mcu.chassis.ratio_right == 10.0
    hw = rig.profile.chassis
    assert rig.mcu.motors["right"].geometry.ratio == hw.ratio_right
    rig.run(0.4)  # the boot
    rig.send("ControlCommand", Command="EnableCanControl")
    rig.drive(0.2, 0.0, 1.0)
    left, right = rig.mcu.encoder_counts()
    assert right == pytest.approx(0.5 * left, rel=1e-3)  # 10/20 of the motor speed ...
    assert rig.mcu.truth.w == pytest.approx((0.1 - 0.2) / hw.wheel_distant, rel=1e-9)


def test_hard_acceleration_slips_by_the_configured_fraction() -> None:
    """accel_slip_*: while a wheel's rim accelerates harder than the threshold, its ground
    speed is (1 - fraction) x its rim speed. With the ramp alone (no lag) the rim accelerates
    at exactly max_wheel_accel to v and back, so each start or stop loses
    fraction x v^2 / (2 a) of ground distance."""
    p = ideal_profile()
    a, s, v = 3.0, 0.4, 0.5
    p = p.replace(motor=dataclasses.replace(p.motor, max_wheel_accel=a),
                  truth=dataclasses.replace(p.truth, accel_slip_threshold=2.0,
                                            accel_slip_fraction=s))
    rig = SimRig(p)
    rig.enable()
    rig.drive(v, 0.0, 1.0)
    ramp = v * v / (2 * a)
    lost = rig.mcu.odometer - rig.mcu.truth.distance
    assert lost == pytest.approx(s * ramp, rel=0.05)
    rig.drive(v, 0.0, 1.0)  # cruising: no slip
    assert rig.mcu.odometer - rig.mcu.truth.distance == pytest.approx(lost, abs=1e-5)  # pulses
    rig.drive(0.0, 0.0, 1.0)  # braking as hard slips as much again
    assert rig.mcu.odometer - rig.mcu.truth.distance == pytest.approx(2 * s * ramp, rel=0.05)
    assert rig.mcu.truth.yaw == pytest.approx(0.0, abs=1e-12)  # both wheels alike


def test_gentle_acceleration_below_the_threshold_does_not_slip() -> None:
    p = ideal_profile()
    p = p.replace(motor=dataclasses.replace(p.motor, max_wheel_accel=1.0),
                  truth=dataclasses.replace(p.truth, accel_slip_threshold=2.0,
                                            accel_slip_fraction=0.4))
    rig = SimRig(p)
    rig.enable()
    rig.drive(0.5, 0.0, 1.5)
    assert rig.mcu.odometer - rig.mcu.truth.distance == pytest.approx(0.0, abs=1e-5)
