"""The actuator model against closed forms: impedance law, damped decay, heating."""

from __future__ import annotations

import math

import pytest

from lowerbase.legged.actuator import Actuator, mit_torque
from lowerbase.legged.figures import actuator
from lowerbase.protocol.legged import ActuatorError, Special


def test_impedance_law_and_saturation() -> None:
    assert mit_torque(0.1, -0.2, 0.3, 0.4, 50.0, 2.0, 1.5, 18.0) == \
        pytest.approx(50 * 0.2 + 2 * 0.6 + 1.5)
    assert mit_torque(0.0, 0.0, 1.0, 0.0, 500.0, 0.0, 0.0, 18.0) == 18.0
    assert mit_torque(0.0, 0.0, -1.0, 0.0, 500.0, 0.0, 0.0, 18.0) == -18.0


def test_velocity_damping_decays_exponentially() -> None:
    params = actuator(6.0, damping=0.0)
    a = Actuator(params)
    a.special(Special.ENTER_MOTOR_MODE)
    a.velocity = 2.0
    kd, dt = 0.5, 1e-5
    a.set_command(0.0, 0.0, 0.0, kd, 0.0)
    for _ in range(1000):
        a.step(dt)
    expected = 2.0 * math.exp(-kd * 0.01 / params.inertia)
    assert a.velocity == pytest.approx(expected, rel=2e-3)


def test_no_torque_outside_motor_mode() -> None:
    a = Actuator(actuator(6.0))
    a.set_command(1.0, 0.0, 100.0, 0.0, 5.0)
    a.step(0.001)
    assert a.torque == 0.0 and a.position == 0.0


def test_winding_heats_as_the_first_order_closed_form() -> None:
    params = actuator(6.0)
    a = Actuator(params, ambient_c=25.0)
    a.special(Special.ENTER_MOTOR_MODE)
    a.set_command(0.0, 0.0, 0.0, 0.0, 9.0)  # constant torque, joint held by the load
    for _ in range(600):
        a.step(0.1, external_torque=-9.0)
    i_q = 9.0 / (params.kt * params.gear_ratio)
    rise = 1.5 * params.phase_resistance * i_q ** 2 * params.thermal_resistance
    assert a.temperature == pytest.approx(
        25.0 + rise * (1 - math.exp(-60.0 / params.thermal_time_constant)), rel=1e-9)


def test_over_temperature_faults_derates_and_clears() -> None:
    params = actuator(6.0, thermal_time_constant=5.0, derate_c=40.0, fault_c=50.0,
                      clear_c=35.0, thermal_resistance=20.0)
    a = Actuator(params)
    a.special(Special.ENTER_MOTOR_MODE)
    a.temperature = 45.0
    assert a.torque_limit() == pytest.approx(params.torque_max * 0.75)
    a.set_command(0.0, 0.0, 0.0, 0.0, 9.0)
    t = 0.0
    while a.error is ActuatorError.NORMAL and t < 100:
        a.step(0.01, external_torque=-9.0)
        t += 0.01
    assert a.error is ActuatorError.MOTOR_OVER_TEMPERATURE and not a.motor_mode
    a.special(Special.ENTER_MOTOR_MODE)
    assert not a.motor_mode  # still hot
    while a.temperature >= params.clear_c:
        a.step(0.1)
    a.special(Special.ENTER_MOTOR_MODE)
    assert a.motor_mode and a.error is ActuatorError.NORMAL


def test_zero_position() -> None:
    a = Actuator(actuator(6.0), position=0.7)
    a.special(Special.ZERO_POSITION)
    assert a.reported_position == 0.0
