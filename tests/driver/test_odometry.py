"""WheelOdometry against closed-form answers (no ROS, no wall clock)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.driver.odometry import (
    INT32_MAX,
    INT32_MIN,
    SMALL_ANGULAR_STEP,
    OdometryNoise,
    OdometryParameters,
    WheelOdometry,
    integrate_exact,
    integrate_runge_kutta2,
    normalize_angle,
    wrap_delta_int32,
)
from lowerbase.errors import ConfigError

# physical-data.md 3.2: 0.2 m wheel, 0.5 m track, 20:1, 10000 pulses per motor turn
PARAMS = OdometryParameters(
    wheel_perimeter=0.2 * math.pi,
    wheel_distant=0.5,
    ratio_left=20.0,
    ratio_right=20.0,
    pulse_per_circle=10000,
)
MPP = PARAMS.metres_per_pulse_left  # [m/pulse]
TRACK = PARAMS.wheel_distant


def wrap32(n: int) -> int:
    """Python int -> the int32 a hardware counter shows."""
    return (n + 2**31) % 2**32 - 2**31


def drive(
    odo: WheelOdometry,
    left_per_step: int,
    right_per_step: int,
    steps: int,
    dt: float = 0.02,
    start: tuple[int, int] = (0, 0),
    t0: float = 0.0,
) -> tuple[int, int, float]:
    """Feed constant pulse increments; returns the final raw counts and time."""
    left, right = start
    odo.update(wrap32(left), wrap32(right), t0)
    t = t0
    for _ in range(steps):
        left += left_per_step
        right += right_per_step
        t += dt
        odo.update(wrap32(left), wrap32(right), t)
    return left, right, t


# -- counter wrap ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("previous", "current", "delta"),
    [
        (0, 0, 0),
        (100, 250, 150),
        (250, 100, -150),
        (2**31 - 10, -(2**31) + 5, 15),
        (-(2**31) + 5, 2**31 - 10, -15),
        (INT32_MAX, INT32_MIN, 1),
        (INT32_MIN, INT32_MAX, -1),
        (-1, 0, 1),
        (0, INT32_MAX, INT32_MAX),
    ],
)
def test_wrap_delta_int32(previous: int, current: int, delta: int) -> None:
    assert wrap_delta_int32(previous, current) == delta


def test_wrap_delta_matches_modular_arithmetic() -> None:
    rng = np.random.default_rng(7)
    for _ in range(2000):
        start = int(rng.integers(INT32_MIN, INT32_MAX, endpoint=True))
        step = int(rng.integers(-(2**31), 2**31 - 1))
        assert wrap_delta_int32(start, wrap32(start + step)) == step


def test_driving_across_the_wrap_equals_driving_from_zero() -> None:
    a, b = WheelOdometry(PARAMS), WheelOdometry(PARAMS)
    drive(a, 5000, 5200, 400)
    drive(b, 5000, 5200, 400, start=(2**31 - 700_000, 2**31 - 1_000_000))
    assert (b.x, b.y, b.yaw) == pytest.approx((a.x, a.y, a.yaw), abs=1e-12)
    assert b.rejected_updates == 0


# -- closed-form motions ----------------------------------------------------------------------


def test_straight_line() -> None:
    odo = WheelOdometry(PARAMS)
    drive(odo, 3183, 3183, 500)  # 0.5 m/s
    d = 3183 * 500 * MPP
    assert (odo.x, odo.y, odo.yaw) == pytest.approx((d, 0.0, 0.0), abs=1e-12)
    assert odo.linear == pytest.approx(3183 * MPP / 0.02, rel=1e-12)
    assert odo.angular == 0.0
    assert odo.distance_travelled == pytest.approx(d, rel=1e-12)


def test_backwards_decreases_x() -> None:
    odo = WheelOdometry(PARAMS, noise=OdometryNoise())
    drive(odo, -1000, -1000, 100)
    assert odo.x == pytest.approx(-1000 * 100 * MPP, rel=1e-12)
    assert odo.linear < 0


def test_rotation_in_place() -> None:
    odo = WheelOdometry(PARAMS)
    per_step = 2000
    steps = 400
    drive(odo, -per_step, per_step, steps)
    yaw = 2 * per_step * steps * MPP / TRACK  # counter-clockwise
    assert odo.yaw_unwrapped == pytest.approx(yaw, rel=1e-12)
    assert odo.yaw == pytest.approx(normalize_angle(yaw), abs=1e-12)
    assert (odo.x, odo.y) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert odo.angular == pytest.approx(2 * per_step * MPP / TRACK / 0.02, rel=1e-12)
    assert odo.linear == 0.0


@pytest.mark.parametrize(
    ("left", "right"), [(3000, 4000), (4000, 3000), (-1500, 2500), (100, 9000), (-3000, -4000)]
)
def test_constant_wheel_speeds_drive_a_circle(left: int, right: int) -> None:
    dt, steps = 0.02, 1500
    odo = WheelOdometry(PARAMS)
    drive(odo, left, right, steps, dt)
    vl, vr = left * MPP / dt, right * MPP / dt
    radius = TRACK / 2 * (vr + vl) / (vr - vl)
    omega = (vr - vl) / TRACK
    t = steps * dt
    theta = omega * t
    expected = (radius * math.sin(theta), radius * (1 - math.cos(theta)), theta)
    assert (odo.x, odo.y, odo.yaw_unwrapped) == pytest.approx(expected, abs=1e-9)
    assert abs(normalize_angle(odo.yaw - theta)) < 1e-9
    assert odo.linear == pytest.approx((vr + vl) / 2, rel=1e-12)
    assert odo.angular == pytest.approx(omega, rel=1e-12)


def test_unequal_ratios_and_perimeter_scale_each_wheel() -> None:
    params = OdometryParameters(0.5, 0.4, ratio_left=10.0, ratio_right=12.5, pulse_per_circle=4000)
    odo = WheelOdometry(params)
    drive(odo, 400, 500, 100)  # one wheel turn each in 2 s
    assert odo.x == pytest.approx(0.5, rel=1e-12)
    assert odo.linear == pytest.approx(0.25, rel=1e-12)
    assert odo.yaw == pytest.approx(0.0, abs=1e-12)


def test_nearly_straight_motion_uses_the_fallback_and_stays_exact() -> None:
    # 1 pulse of difference per step: dtheta = 6.3e-6 rad per step (exact arc) with the
    # standard encoder, 6.3e-8 rad (Runge-Kutta 2 fallback) with a 100x finer one
    dt = 0.02
    fine = OdometryParameters(0.2 * math.pi, 0.5, 20.0, 20.0, 1_000_000)
    for params, left, right, steps in (
        (PARAMS, 10_000, 10_001, 3000),
        (fine, 100_000, 100_001, 3000),
        (fine, 10, 11, 3000),
    ):
        mpp = params.metres_per_pulse_left
        odo = WheelOdometry(params)
        drive(odo, left, right, steps, dt)
        assert odo.rejected_updates == 0
        vl, vr = left * mpp / dt, right * mpp / dt
        omega = (vr - vl) / TRACK
        radius = TRACK / 2 * (vr + vl) / (vr - vl)
        theta = omega * steps * dt
        exp_x, exp_y = radius * math.sin(theta), radius * (1 - math.cos(theta))
        scale = max(abs(exp_x), 1.0)
        assert odo.x == pytest.approx(exp_x, abs=1e-12 * scale)
        assert odo.y == pytest.approx(exp_y, abs=1e-11 * scale)
        assert odo.yaw == pytest.approx(theta, abs=1e-13)


def test_runge_kutta2_fallback_agrees_with_the_exact_arc() -> None:
    for yaw in (0.0, 0.7, -2.5, math.pi):
        for ds in (1e-3, 0.05, -0.3):
            for dyaw in (1e-7, -5e-7, 0.99e-6, 1.01e-6, 1e-5):
                exact = integrate_exact(1.0, -2.0, yaw, ds, dyaw, small_angular=0.0)
                rk2 = integrate_runge_kutta2(1.0, -2.0, yaw, ds, dyaw)
                # the RK2 position error is |ds| * dyaw^2 / 24; the arc formula itself loses
                # |ds / dyaw| * eps to cancellation (why the fallback exists)
                tol = abs(ds) * dyaw**2 / 20 + abs(ds / dyaw) * 1e-15 + 1e-15
                assert rk2 == pytest.approx(exact, abs=tol)
    # and integrate_exact switches at the threshold
    below = integrate_exact(0, 0, 0.3, 0.1, 0.5 * SMALL_ANGULAR_STEP)
    assert below == integrate_runge_kutta2(0, 0, 0.3, 0.1, 0.5 * SMALL_ANGULAR_STEP)


def test_exact_arc_quarter_circle() -> None:
    x, y, yaw = integrate_exact(0.0, 0.0, 0.0, math.pi / 2, math.pi / 2)  # radius 1
    assert (x, y, yaw) == pytest.approx((1.0, 1.0, math.pi / 2), abs=1e-15)


# -- timing, NaN, jumps -----------------------------------------------------------------------


def test_first_update_only_sets_the_baseline() -> None:
    odo = WheelOdometry(PARAMS)
    assert odo.update(123456, -98765, 10.0) is False
    assert odo.has_baseline
    assert (odo.x, odo.y, odo.yaw) == (0.0, 0.0, 0.0)
    assert odo.update(123456 + 1000, -98765 + 1000, 10.02) is True
    assert odo.x == pytest.approx(1000 * MPP)


def test_tiny_dt_integrates_pose_but_not_velocity() -> None:
    odo = WheelOdometry(PARAMS, min_dt=1e-3)
    odo.update(0, 0, 0.0)
    assert odo.update(1000, 1000, 0.02) is True
    assert odo.update(1500, 1500, 0.02 + 1e-5) is False  # too short for a speed
    assert odo.x == pytest.approx(1500 * MPP)  # no pulse lost
    assert odo.linear == pytest.approx(1000 * MPP / 0.02)
    assert odo.update(2000, 2000, 0.04) is True
    assert odo.linear == pytest.approx(1000 * MPP / 0.02)  # over the whole interval


def test_non_finite_and_backwards_samples_are_ignored() -> None:
    odo = WheelOdometry(PARAMS)
    odo.update(0, 0, 0.0)
    odo.update(1000, 1000, 0.02)
    before = (odo.x, odo.y, odo.yaw, odo.linear)
    assert odo.update(5000, 5000, math.nan) is False
    assert odo.update(5000, 5000, math.inf) is False
    assert odo.update(math.nan, 5000, 0.04) is False  # type: ignore[arg-type]
    assert odo.update(2000.5, 2000, 0.04) is False  # type: ignore[arg-type]
    assert odo.update(5000, 5000, 0.01) is False  # time went backwards
    assert (odo.x, odo.y, odo.yaw, odo.linear) == before
    assert odo.rejected_updates == 5
    odo.integrate(math.nan, 0.0)
    assert odo.x == before[0]
    # numpy integers are counts too
    assert odo.update(np.int32(2000), np.int64(2000), 0.04) is True
    assert odo.x == pytest.approx(2000 * MPP)


def test_counter_reset_rebaselines_instead_of_teleporting() -> None:
    odo = WheelOdometry(PARAMS, max_wheel_speed=5.0)
    drive(odo, 3000, 3000, 100)
    x = odo.x
    odo.update(0, 0, 2.02)  # lower computer rebooted: counters back at zero
    assert odo.x == x
    assert odo.rejected_updates == 1
    odo.update(3000, 3000, 2.04)
    assert odo.x == pytest.approx(x + 3000 * MPP)


def test_reset_and_reset_baseline() -> None:
    odo = WheelOdometry(PARAMS)
    drive(odo, 3000, 3100, 50)
    odo.reset_baseline()
    assert not odo.has_baseline and odo.x != 0.0
    odo.reset(1.0, 2.0, 3.0)
    assert (odo.x, odo.y, odo.yaw, odo.linear, odo.distance_travelled) == (1.0, 2.0, 3.0, 0.0, 0.0)
    assert math.isnan(odo.stamp)


# -- covariances ----------------------------------------------------------------------------


def _cov(odo: WheelOdometry) -> np.ndarray:
    return np.array(odo.pose_covariance).reshape(3, 3)


def test_pose_covariance_straight_line_closed_form() -> None:
    noise = OdometryNoise(
        scale_error=0.01,
        heading_error_per_metre=0.02,
        heading_error_per_radian=0.03,
        position_floor=0.0,
        yaw_floor=0.0,
    )
    odo = WheelOdometry(PARAMS, noise)
    drive(odo, 3183, 3183, 1000)
    d = odo.x
    p = _cov(odo)
    assert math.sqrt(p[0, 0]) == pytest.approx(0.01 * d, rel=1e-9)  # along track: scale error
    assert math.sqrt(p[2, 2]) == pytest.approx(0.02 * d, rel=1e-9)  # heading: E_d drift
    # a heading error growing linearly with distance bends the path: lateral d^2/2
    assert math.sqrt(p[1, 1]) == pytest.approx(0.02 * d**2 / 2, rel=1e-3)
    assert p[1, 2] == pytest.approx(0.02**2 * d**3 / 2, rel=1e-3)


def test_pose_covariance_rotation_in_place_closed_form() -> None:
    noise = OdometryNoise(heading_error_per_radian=0.02, position_floor=0.0, yaw_floor=0.0)
    odo = WheelOdometry(PARAMS, noise)
    per_step = 2000
    steps = round(math.tau * TRACK / (2 * per_step * MPP))
    drive(odo, -per_step, per_step, steps)
    p = _cov(odo)
    assert math.sqrt(p[2, 2]) == pytest.approx(0.02 * odo.angle_turned, rel=1e-12)
    assert p[0, 0] == pytest.approx(0.0, abs=1e-30) and p[1, 1] == pytest.approx(0.0, abs=1e-30)


def test_pose_covariance_is_independent_of_the_update_rate() -> None:
    fine, coarse = WheelOdometry(PARAMS), WheelOdometry(PARAMS)
    drive(fine, 3000, 3400, 1000, dt=0.01)
    drive(coarse, 30000, 34000, 100, dt=0.1)
    assert (coarse.x, coarse.y, coarse.yaw) == pytest.approx((fine.x, fine.y, fine.yaw), abs=1e-9)
    np.testing.assert_allclose(_cov(coarse), _cov(fine), rtol=2e-3, atol=1e-12)


def test_pose_covariance_is_honest_symmetric_and_grows() -> None:
    odo = WheelOdometry(PARAMS)
    p0 = _cov(odo)
    assert np.all(np.diag(p0) > 0)  # floors: never a zero (overconfident) covariance
    rng = np.random.default_rng(3)
    left = right = 0
    odo.update(0, 0, 0.0)
    previous_yaw_var = p0[2, 2]
    for k in range(1, 400):
        left += int(rng.integers(1000, 5000))
        right += int(rng.integers(1000, 5000))
        odo.update(left, right, k * 0.02)
        p = _cov(odo)
        np.testing.assert_allclose(p, p.T, atol=1e-18)
        assert np.all(np.linalg.eigvalsh(p) > 0)
        assert p[2, 2] >= previous_yaw_var  # heading errors accumulate, never cancel
        previous_yaw_var = p[2, 2]
    assert np.trace(p) > 10 * np.trace(p0)


def test_twist_covariance() -> None:
    noise = OdometryNoise()
    odo = WheelOdometry(PARAMS, noise)
    assert odo.twist_covariance == (
        noise.linear_velocity_floor**2,
        0.0,
        0.0,
        noise.angular_velocity_floor**2,
    )
    drive(odo, 3183, 3183, 10)
    var_v, _, _, var_w = odo.twist_covariance
    v = odo.linear
    q = MPP**2 / 6 / 0.02**2  # quantisation of one wheel's speed
    assert var_v == pytest.approx(
        q / 2 + (noise.scale_error * v) ** 2 + noise.linear_velocity_floor**2, rel=1e-12
    )
    assert var_w == pytest.approx(
        2 * q / TRACK**2
        + (noise.heading_error_per_metre * v) ** 2
        + noise.angular_velocity_floor**2,
        rel=1e-12,
    )


def test_state_snapshot_and_ros_matrices() -> None:
    odo = WheelOdometry(PARAMS)
    drive(odo, 3000, 3500, 100)
    s = odo.state()
    assert (s.x, s.y, s.yaw, s.linear, s.angular) == (
        odo.x,
        odo.y,
        odo.yaw,
        odo.linear,
        odo.angular,
    )
    assert s.stamp == pytest.approx(2.0)
    pose6 = np.array(s.ros_pose_covariance()).reshape(6, 6)
    p3 = np.array(s.pose_covariance).reshape(3, 3)
    idx = [0, 1, 5]
    np.testing.assert_array_equal(pose6[np.ix_(idx, idx)], p3)
    assert pose6[2, 2] == pose6[3, 3] == pose6[4, 4] == 1e6
    twist6 = np.array(s.ros_twist_covariance(unobserved_variance=1e3)).reshape(6, 6)
    assert twist6[0, 0] == s.twist_covariance[0] and twist6[5, 5] == s.twist_covariance[3]
    assert twist6[2, 2] == 1e3


# -- parameters ----------------------------------------------------------------------------


def test_parameters_from_lower_computer() -> None:
    p = OdometryParameters.from_lower_computer(
        {
            "wheelPerimeter": 0.6283,
            "wheelDistant": 0.5,
            "ratioLeft": 20.0,
            "ratioRight": 21.0,
            "pulsePerCircle": 10000.0,
            "maxRPM": 3000.0,
        }
    )
    assert p.metres_per_pulse_left == pytest.approx(0.6283 / 200000)
    assert p.metres_per_pulse_right == pytest.approx(0.6283 / 210000)
    with pytest.raises(ConfigError, match="ratioRight"):
        OdometryParameters.from_lower_computer(
            {"wheelPerimeter": 1, "wheelDistant": 1, "ratioLeft": 1, "pulsePerCircle": 1}
        )


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_parameters_are_validated(bad: float) -> None:
    with pytest.raises(ConfigError):
        OdometryParameters(0.6, bad, 20.0, 20.0, 10000)
    with pytest.raises(ConfigError):
        OdometryNoise(scale_error=bad if bad != 0.0 else -1.0)
