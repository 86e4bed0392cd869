"""Differential-drive kinematics and the hard limits, against closed-form answers."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lowerbase.firmware_model.kinematics import (
    limit_twist,
    max_rim_speed,
    motor_rpm_to_wheel_rad_s,
    rim_speed_to_wheel_rad_s,
    twist_from_wheel_speeds,
    wheel_rad_s_to_motor_rpm,
    wheel_rad_s_to_rim_speed,
    wheel_speeds_from_twist,
)
from lowerbase.firmware_model.profile import ChassisParams

CHASSIS = ChassisParams()
# 3000 rpm / 20 = 150 rpm at the wheel = 2.5 rev/s * 0.6283 m
RIM_AT_MAX_RPM = 2.5 * 0.6283


def test_inverse_and_forward_kinematics() -> None:
    assert wheel_speeds_from_twist(1.0, 0.0, 0.5) == (1.0, 1.0)
    assert wheel_speeds_from_twist(0.0, 2.0, 0.5) == (-0.5, 0.5)
    assert wheel_speeds_from_twist(1.0, 1.0, 0.5) == (0.75, 1.25)
    assert twist_from_wheel_speeds(0.75, 1.25, 0.5) == (1.0, 1.0)


def test_unit_conversions() -> None:
    wheel = rim_speed_to_wheel_rad_s(RIM_AT_MAX_RPM, 0.6283)
    assert wheel == pytest.approx(2.5 * 2 * math.pi)
    assert wheel_rad_s_to_motor_rpm(wheel, 20.0) == pytest.approx(3000.0)
    assert motor_rpm_to_wheel_rad_s(3000.0, 20.0) == pytest.approx(wheel)
    assert wheel_rad_s_to_rim_speed(wheel, 0.6283) == pytest.approx(RIM_AT_MAX_RPM)


def test_max_rim_speed_is_the_lower_of_max_speed_and_max_rpm() -> None:
    assert max_rim_speed(CHASSIS, "left") == 1.5  # maxSpeed 1.5 < 1.571 at maxRPM
    fast = replace(CHASSIS, max_speed=10.0)
    assert max_rim_speed(fast, "left") == pytest.approx(RIM_AT_MAX_RPM)
    geared = replace(fast, ratio_right=40.0)
    assert max_rim_speed(geared, "right") == pytest.approx(RIM_AT_MAX_RPM / 2)


def test_limit_twist_passes_commands_within_limits() -> None:
    assert limit_twist(0.5, -0.3, CHASSIS) == (0.5, -0.3, False, True)


def test_limit_twist_clips_linear_and_angular_independently() -> None:
    assert limit_twist(2.0, 0.0, CHASSIS) == (1.2, 0.0, True, True)
    assert limit_twist(0.0, -3.0, CHASSIS) == (0.0, -1.0, True, True)


def test_max_rpm_scales_both_wheels_and_preserves_curvature() -> None:
    params = replace(CHASSIS, max_speed=10.0, max_linear=3.0, max_angular=6.0)
    v, w, clipped, valid = limit_twist(2.0, 1.0, params)
    assert clipped and valid
    assert w / v == pytest.approx(0.5)  # curvature unchanged
    v_l, v_r = wheel_speeds_from_twist(v, w, params.wheel_distant)
    assert v_r == pytest.approx(RIM_AT_MAX_RPM)  # the faster wheel sits at maxRPM
    assert v_l == pytest.approx(RIM_AT_MAX_RPM * 1.75 / 2.25)


def test_non_finite_commands_are_flagged_invalid() -> None:
    for v, w in [(math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan)]:
        assert limit_twist(v, w, CHASSIS) == (0.0, 0.0, True, False)


@settings(max_examples=60, deadline=None)
@given(st.floats(-3, 3), st.floats(-6, 6), st.floats(5.0, 60.0))
def test_limited_wheel_speeds_never_exceed_the_limits(v: float, w: float, ratio: float) -> None:
    params = replace(CHASSIS, ratio_left=ratio, max_linear=3.0, max_angular=6.0)
    out = limit_twist(v, w, params)
    v_l, v_r = wheel_speeds_from_twist(out.v, out.w, params.wheel_distant)
    assert abs(v_l) <= max_rim_speed(params, "left") * (1 + 1e-12)
    assert abs(v_r) <= max_rim_speed(params, "right") * (1 + 1e-12)
    assert out.v * v >= 0 and out.w * w >= 0  # never reverses a command
