"""Wheel motor + driver: ramp, lag, deadband, current and faults against closed forms."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from lowerbase.firmware_model.motor import (
    STATUS_OVER_CURRENT,
    STATUS_STALLED,
    WheelGeometry,
    WheelMotor,
)
from lowerbase.firmware_model.profile import STANDARD_GRAVITY, ChassisParams, MotorParams

GEOMETRY = WheelGeometry.from_chassis(ChassisParams(), "left")
R = GEOMETRY.radius  # 0.6283 / 2pi
IDEAL = MotorParams(time_constant=0.0, max_wheel_accel=0.0)


def run(
    motor: WheelMotor, target: float, seconds: float, dt: float = 0.005, brake: bool = False
) -> float:
    angle = 0.0
    for _ in range(round(seconds / dt)):
        angle += motor.step(target, dt, brake=brake)
    return angle


def test_ideal_motor_follows_the_target_exactly() -> None:
    motor = WheelMotor(IDEAL, GEOMETRY)
    assert motor.step(7.0, 0.01) == pytest.approx(0.07)
    assert motor.omega == 7.0
    assert motor.rim_speed == pytest.approx(7.0 * R)
    assert motor.motor_rpm == pytest.approx(7.0 * 20 * 60 / (2 * math.pi))


def test_accel_ramp_gives_a_times_t_until_the_target() -> None:
    a = 2.0  # [m/s^2] at the rim
    motor = WheelMotor(replace(IDEAL, max_wheel_accel=a), GEOMETRY)
    angle = run(motor, 1.0 / R, 0.2)
    assert motor.rim_speed == pytest.approx(a * 0.2)
    assert angle * R == pytest.approx(0.5 * a * 0.2**2)
    angle += run(motor, 1.0 / R, 0.8)  # target 1 m/s reached at 0.5 s
    assert motor.rim_speed == pytest.approx(1.0)
    assert angle * R == pytest.approx(0.5 * a * 0.5**2 + 1.0 * 0.5)


def test_first_order_lag_matches_the_exponential() -> None:
    tau = 0.05
    motor = WheelMotor(replace(IDEAL, time_constant=tau), GEOMETRY)
    angle = run(motor, 10.0, 0.12)
    assert motor.omega == pytest.approx(10.0 * (1 - math.exp(-0.12 / tau)))
    assert angle == pytest.approx(10.0 * (0.12 - tau * (1 - math.exp(-0.12 / tau))))


def test_ramp_plus_lag_is_exact_and_step_size_invariant() -> None:
    params, tau, a = MotorParams(), 0.05, 3.0
    coarse, fine = WheelMotor(params, GEOMETRY), WheelMotor(params, GEOMETRY)
    coarse_angle = coarse.step(1.2 / R, 0.3)
    fine_angle = run(fine, 1.2 / R, 0.3, dt=0.001)
    assert fine.omega == pytest.approx(coarse.omega) and fine_angle == pytest.approx(coarse_angle)
    t = 0.3  # still ramping (1.2 m/s needs 0.4 s): w = a (t - tau (1 - e^-t/tau)) / r
    assert coarse.rim_speed == pytest.approx(a * (t - tau * (1 - math.exp(-t / tau))))


def test_deadband_below_min_speed() -> None:
    motor = WheelMotor(IDEAL, GEOMETRY)
    assert run(motor, 0.004 / R, 0.1) == 0.0 and motor.omega == 0.0
    assert run(motor, -0.006 / R, 0.1) < 0.0


def test_max_rpm_caps_the_wheel_speed() -> None:
    motor = WheelMotor(IDEAL, GEOMETRY)
    motor.step(100.0, 0.01)
    assert motor.motor_rpm == pytest.approx(3000.0)


def test_brake_ramps_to_zero_at_the_driver_ramp() -> None:
    motor = WheelMotor(MotorParams(time_constant=0.0), GEOMETRY)  # ramp 3 m/s^2
    run(motor, 1.0 / R, 1.0)
    run(motor, 1.0 / R, 0.2, brake=True)
    assert motor.rim_speed == pytest.approx(1.0 - 3.0 * 0.2)
    run(motor, 1.0 / R, 0.5, brake=True)
    assert motor.omega == 0.0


def rim_current(params: MotorParams, force: float, motoring: bool = True) -> float:
    eta, n, kt = params.gear_efficiency, GEOMETRY.ratio, params.torque_constant
    torque = force * R / (n * eta) if motoring else force * R * eta / n
    return torque / kt + math.copysign(params.idle_current, torque)


def test_current_covers_friction_inertia_and_regeneration() -> None:
    p = MotorParams(time_constant=0.0, max_wheel_accel=2.0)
    m = 0.5 * p.robot_mass
    friction = p.rolling_resistance * m * STANDARD_GRAVITY
    motor = WheelMotor(p, GEOMETRY)
    assert motor.step(0.0, 0.01) == 0.0
    assert motor.current == p.idle_current
    motor.step(1.0 / R, 0.1)  # accelerating at 2 m/s^2, ends at 0.2 m/s
    expected = rim_current(p, m * 2.0 + friction + p.viscous_friction * 0.2)
    assert motor.current == pytest.approx(expected)
    run(motor, 1.0 / R, 1.0)  # steady 1 m/s
    assert motor.current == pytest.approx(rim_current(p, friction + p.viscous_friction * 1.0))
    motor.step(0.0, 0.1)  # braking at 2 m/s^2 from 1 m/s: the motor regenerates
    force = -m * 2.0 + friction + p.viscous_friction * 0.8
    assert motor.current == pytest.approx(rim_current(p, force, motoring=False))
    assert motor.current < 0


def test_blocked_wheel_stalls_then_trips_over_current() -> None:
    p = MotorParams()  # stall after 0.3 s, over-current after 0.5 s above 20 A
    motor = WheelMotor(p, GEOMETRY)
    motor.blocked = True
    run(motor, 0.5 / R, 0.25)
    assert motor.omega == 0.0 and motor.current == p.stall_current + p.idle_current
    assert motor.status_bits == 0
    run(motor, 0.5 / R, 0.1)
    assert motor.status_bits == STATUS_STALLED
    run(motor, 0.5 / R, 0.2)
    assert motor.status_bits == STATUS_STALLED | STATUS_OVER_CURRENT
    run(motor, 0.5 / R, 0.5)  # the tripped driver ramps its setpoint down and stops pushing
    assert motor.setpoint == 0.0 and motor.current == p.idle_current
    motor.blocked = False
    motor.clear_faults()
    run(motor, 0.5 / R, 1.0)
    assert motor.status_bits == 0 and motor.rim_speed == pytest.approx(0.5, rel=1e-6)


def test_injected_over_current_brakes_until_cleared() -> None:
    motor = WheelMotor(MotorParams(time_constant=0.0), GEOMETRY)
    run(motor, 1.0 / R, 1.0)
    motor.inject_over_current()
    run(motor, 1.0 / R, 0.1)
    assert motor.rim_speed == pytest.approx(1.0 - 0.3)
    assert motor.status_bits == STATUS_OVER_CURRENT
    motor.clear_faults()
    run(motor, 1.0 / R, 0.2)
    assert motor.rim_speed == pytest.approx(1.0)


def test_normal_driving_raises_no_fault() -> None:
    motor = WheelMotor(MotorParams(), GEOMETRY)
    peak = 0.0
    for target in (1.5, -1.5, 0.0, 0.02, 0.0):
        for _ in range(300):
            motor.step(target / R, 0.005)
            peak = max(peak, abs(motor.current))
    assert motor.status_bits == 0
    assert peak < MotorParams().over_current_limit


def _state(m: WheelMotor) -> tuple[float, ...]:
    return (m.omega, m.setpoint, m.current, m._over_time, m._stall_time, float(m.over_current),
            float(m.stalled))


@pytest.mark.parametrize("params", [MotorParams(), replace(MotorParams(), over_current_limit=0.9,
                                                           over_current_time=2.5)])
def test_the_steady_speed_shortcut_is_the_full_step_bit_for_bit(params: MotorParams) -> None:
    """At a steady speed (the lag's fixed point to the last bit) ``step`` skips the arithmetic
    it would repeat on the same floats: angle and state stay those of the full step (the
    reference forgets the fixed point before every step), the fault timers still run (an
    over-current limit below the cruising current still latches), and a new target, a load
    force or a blocked wheel leave the shortcut at once."""
    fast, full = WheelMotor(params, GEOMETRY), WheelMotor(params, GEOMETRY)
    plan = [(12.0, 0.0, False)] * 600 + [(12.0, 3.0, False)] * 5 + [(12.0, 0.0, True)] * 5 \
        + [(12.0, 0.0, False)] * 600 + [(-8.0, 0.0, False)] * 600 + [(0.0, 0.0, False)] * 200
    shortcuts = 0
    for target, load, blocked in plan:
        fast.blocked = full.blocked = blocked
        full._steady = None
        shortcuts += fast._steady is not None
        assert fast.step(target, 0.005, load_force=load) == full.step(target, 0.005,
                                                                      load_force=load)
        assert _state(fast) == _state(full)
    latched = params.over_current_limit == 0.9  # below the 0.93 A at 12 rad/s: after 2.5 s
    assert fast.over_current == latched
    assert shortcuts > (50 if latched else 500)


def pressed_run(motor: WheelMotor, target: float, periods: int, dt: float = 0.005) -> float:
    """Each period stepped free, then redone as pressed (what the MCU does for a refused
    move): the angle [rad] the wheel really turned."""
    angle = 0.0
    for _ in range(periods):
        state = motor.save()
        motor.step(target, dt)
        angle += motor.press(state, target, dt, brake=False)
    return angle


def test_pressed_against_the_world_the_default_motor_slips_on_the_traction() -> None:
    p = MotorParams()
    motor = WheelMotor(p, GEOMETRY)
    run(motor, 5.0, 2.0)  # cruising at 5 rad/s (0.5 m/s)
    f_t = p.traction * 0.5 * p.robot_mass * STANDARD_GRAVITY  # 441 N
    assert motor.traction_force == pytest.approx(f_t)
    assert motor.stall_force == pytest.approx(25.0 * 0.15 * 20 * 0.9 / R)  # 675 N
    assert not motor.held
    angle = pressed_run(motor, 5.0, 100)
    assert angle == pytest.approx(5.0 * 0.5, rel=1e-6)  # the tyre slips, the wheel turns on
    amps = f_t * R / (GEOMETRY.ratio * p.gear_efficiency * p.torque_constant)
    assert motor.current == pytest.approx(amps + p.idle_current, rel=1e-12)  # 16.6 A
    assert motor.status_bits == 0


def test_pressed_against_the_world_a_held_wheel_stalls_after_stall_time() -> None:
    p = MotorParams(robot_mass=250.0)  # 736 N of traction against 675 N of motor
    motor = WheelMotor(p, GEOMETRY)
    run(motor, 5.0, 2.0)
    assert motor.held
    dt = 0.005
    n = math.ceil(p.stall_time / dt - 1e-9)  # periods until the timer reaches stall_time
    assert pressed_run(motor, 5.0, n - 1, dt) == 0.0
    assert motor.omega == 0.0 and motor.current == p.stall_current + p.idle_current
    assert not motor.stalled
    pressed_run(motor, 5.0, 1, dt)
    assert motor.stalled and motor.status_bits & STATUS_STALLED
    assert not motor.pressed  # only for the redone step
