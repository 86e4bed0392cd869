"""PlanarEkf: model pieces against numerics, and a synthetic run against the truth.

The synthetic run is the COMPASS P6 situation of physical-data.md 5.2: the right wheel's radius
is 1.5 % larger than the parameters say, the left wheel spins free for 0.4 s once, and a z-gyro
with a 0.01 rad/s bias, 0.2 % scale error and 2 mrad/s noise is available. Deterministic: fixed
seeds, simulated time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pytest

from lowerbase.driver.ekf import (
    DIM_X,
    YAW,
    B,
    EkfNoise,
    Gate,
    PlanarEkf,
    V,
    W,
    motion_jacobian,
    motion_model,
    process_noise,
)
from lowerbase.driver.odometry import OdometryParameters, WheelOdometry, normalize_angle
from lowerbase.errors import ConfigError

PARAMS = OdometryParameters(0.2 * math.pi, 0.5, 20.0, 20.0, 10000)
MPP = PARAMS.metres_per_pulse_left
TRACK = PARAMS.wheel_distant
GYRO_LSB = 1e-4  # [rad/s] ImuGyro.Z scale in chassis.dbc


# -- model pieces ---------------------------------------------------------------------------


def test_motion_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        x = rng.normal(size=(DIM_X, 1)) * np.array([[3], [3], [2], [1], [1], [0.1]])
        dt = float(rng.uniform(0.001, 0.1))
        f = motion_jacobian(x, dt)
        num = np.zeros((DIM_X, DIM_X))
        for j in range(DIM_X):
            e = np.zeros((DIM_X, 1))
            e[j, 0] = 1e-6
            num[:, j] = ((motion_model(x + e, dt) - motion_model(x - e, dt)) / 2e-6).ravel()
        np.testing.assert_allclose(f, num, atol=1e-8)


def test_motion_model_constant_turn() -> None:
    x = np.array([[0.0], [0.0], [0.0], [1.0], [0.0], [0.3]])
    out = motion_model(x, 2.0)
    np.testing.assert_allclose(out.ravel(), [2.0, 0.0, 0.0, 1.0, 0.0, 0.3])
    ekf = PlanarEkf(EkfNoise(max_step=0.001))
    ekf.kf.x[V, 0], ekf.kf.x[W, 0] = 1.0, 0.5  # radius 2 m
    ekf.predict(math.pi)  # a quarter circle
    assert ekf.pose == pytest.approx((2.0, 2.0, math.pi / 2), abs=1e-6)


def test_process_noise_is_symmetric_positive_semidefinite() -> None:
    x = np.array([[1.0], [2.0], [0.7], [0.5], [0.2], [0.01]])
    q = process_noise(x, 0.02, EkfNoise())
    np.testing.assert_allclose(q, q.T)
    assert np.all(np.linalg.eigvalsh(q) >= -1e-18)
    assert q[B, B] == pytest.approx(EkfNoise().gyro_bias_walk ** 2 * 0.02)


def test_predict_splits_long_steps_and_keeps_time() -> None:
    ekf = PlanarEkf(EkfNoise(max_step=0.05), stamp=10.0)
    ekf.kf.x[V, 0], ekf.kf.x[W, 0] = 1.0, 1.0
    ekf.predict_to(11.0)
    assert ekf.stamp == 11.0
    exact = (math.sin(1.0), 1 - math.cos(1.0))  # radius 1 m, 1 rad
    assert ekf.pose[:2] == pytest.approx(exact, abs=1e-4)
    np.testing.assert_array_equal(ekf.x_prior, ekf.x)
    ekf.predict_to(10.5)  # late sample: no prediction backwards
    assert ekf.stamp == 11.0
    with pytest.raises(ValueError):
        ekf.predict(-1.0)
    with pytest.raises(ValueError):
        ekf.predict_to(math.nan)


def test_first_stamp_only_sets_the_time() -> None:
    ekf = PlanarEkf()
    assert ekf.stamp is None
    ekf.update_gyro(0.0, stamp=5.0)
    assert ekf.stamp == 5.0


# -- updates and gates ----------------------------------------------------------------------


def test_gyro_measures_rate_plus_bias_and_innovation_is_inspectable() -> None:
    ekf = PlanarEkf()
    gate = ekf.update_gyro(0.05, stamp=0.0)
    assert gate is Gate.ACCEPTED
    assert ekf.innovation.shape == (1, 1) and ekf.innovation[0, 0] == pytest.approx(0.05)
    np.testing.assert_allclose(ekf.kf.y, ekf.innovation)
    w, b = ekf.x[W], ekf.x[B]
    # not at standstill: the bias is a consider state (its value stays, its uncertainty
    # counts), so the rate takes its share of the innovation and the bias none
    assert b == 0.0
    s = float(ekf.innovation_covariance[0, 0])
    p_ww = s - float(ekf.P[B, B]) - 0.002**2 - 0.0  # S = P_ww + P_bb + R (P_bb unchanged)
    assert 0.0 < w < 0.05
    assert w == pytest.approx(0.05 * p_ww / s, rel=0.05)


def test_standstill_makes_the_gyro_measure_pure_bias() -> None:
    rng = np.random.default_rng(11)
    bias = 0.02
    ekf = PlanarEkf()
    t = 0.0
    for k in range(300):  # 3 s at 100 Hz, wheels at 50 Hz
        t = k * 0.01
        ekf.update_gyro(bias + rng.normal(0, 0.002), stamp=t)
        if k % 2 == 0:
            gate = ekf.update_wheels(0.0, 0.0, stamp=t)
            assert gate is (Gate.STANDSTILL if t >= 0.2 - 1e-9 else Gate.ACCEPTED)
    assert ekf.is_standstill
    assert ekf.gyro_bias == pytest.approx(bias, abs=5e-4)
    assert abs(ekf.twist[1]) < 3 * 0.002  # the last gyro sample's noise
    assert math.sqrt(ekf.P[B, B]) < 5e-4
    # heading does not drift while standing although the gyro is biased
    assert abs(ekf.pose[2]) < 1e-3
    # any wheel motion ends standstill at once
    assert ekf.update_wheels(0.01, 0.0, stamp=t + 0.02) is not Gate.STANDSTILL
    assert not ekf.is_standstill


def test_standstill_without_stamps_uses_predicted_time() -> None:
    ekf = PlanarEkf(EkfNoise(standstill_time=0.1))
    assert ekf.update_wheels(0.0, 0.0) is Gate.ACCEPTED
    ekf.predict(0.05)
    assert ekf.update_wheels(0.0, 0.0) is Gate.ACCEPTED
    ekf.predict(0.06)
    assert ekf.update_wheels(0.0, 0.0) is Gate.STANDSTILL


def _settled(bias: float = 0.0) -> PlanarEkf:
    """A filter that has been driving at 0.5 m/s straight with gyro and wheels for 2 s."""
    ekf = PlanarEkf()
    ekf.reset(gyro_bias=bias)
    ekf.kf.P[B, B] = 1e-8
    for k in range(200):
        t = k * 0.01
        ekf.update_gyro(bias, stamp=t)
        if k % 2 == 0:
            ekf.update_wheels(0.5, 0.0, stamp=t)
    return ekf


def test_slipping_wheel_yaw_rate_is_rejected_speed_down_weighted() -> None:
    ekf = _settled()
    v_before = ekf.twist[0]
    # the left wheel spins 0.2 m/s faster: v off by 0.1, w off by -0.4 rad/s
    gate = ekf.update_wheels(0.6, -0.4, stamp=2.0)
    assert gate is Gate.ANGULAR_REJECTED
    assert ekf.mahalanobis_sq > EkfNoise().gate_2dof
    assert abs(ekf.twist[1]) < 1e-3  # the gyro's yaw rate stands
    assert abs(ekf.twist[0] - v_before) < 0.05  # speed only nudged (innovation 0.1)
    assert ekf.statistics["wheel.angular_rejected"] == 1


def test_wild_wheel_measurement_is_rejected_entirely() -> None:
    ekf = _settled()
    x_before = ekf.x
    assert ekf.update_wheels(5.0, 3.0) is Gate.REJECTED
    np.testing.assert_array_equal(ekf.x, x_before)


def test_linear_only_outlier_keeps_the_yaw_rate() -> None:
    ekf = _settled()
    assert ekf.update_wheels(2.0, 0.0) is Gate.LINEAR_REJECTED


def test_gyro_is_the_yaw_rate_reference_by_default() -> None:
    # a wheel that slips makes the true yaw rate jump; only the gyro sees it, so it is not gated
    ekf = _settled()
    t = ekf.stamp
    gates = [ekf.update_gyro(0.8, stamp=t + 0.01 * (k + 1)) for k in range(10)]
    assert gates == [Gate.ACCEPTED] * 10
    assert ekf.twist[1] == pytest.approx(0.8, abs=0.05)  # followed within 0.1 s
    # and the wheels that still claim straight motion are the outlier now
    assert ekf.update_wheels(0.5, 0.0, stamp=t + 0.11) is Gate.ANGULAR_REJECTED


def test_gated_gyro_spike_is_rejected_and_lock_out_is_prevented() -> None:
    ekf = PlanarEkf(EkfNoise(gate_gyro=True))
    ekf.reset()
    ekf.kf.P[B, B] = 1e-8
    for k in range(200):
        ekf.update_gyro(0.0, stamp=k * 0.01)
        if k % 2 == 0:
            ekf.update_wheels(0.5, 0.0, stamp=k * 0.01)
    assert ekf.update_gyro(2.0) is Gate.REJECTED
    assert abs(ekf.twist[1]) < 1e-3
    # a gyro that really moved on is accepted again after too many rejections in a row
    noise = EkfNoise(max_consecutive_rejections=5, gate_gyro=True)
    ekf = PlanarEkf(noise)
    ekf.kf.P[W, W] = ekf.kf.P[B, B] = 1e-10
    gates = [ekf.update_gyro(1.0) for _ in range(7)]
    assert gates[:5] == [Gate.REJECTED] * 5
    assert gates[5] is Gate.FORCED


def test_non_finite_measurements_are_ignored() -> None:
    ekf = PlanarEkf()
    x = ekf.x
    assert ekf.update_gyro(math.nan) is Gate.INVALID
    assert ekf.update_wheels(math.inf, 0.0) is Gate.INVALID
    np.testing.assert_array_equal(ekf.x, x)
    with pytest.raises(ValueError):
        ekf.update_wheels(0.1, 0.0, covariance=(math.nan, 0.0, 0.0, 1.0))


def test_noise_is_validated() -> None:
    with pytest.raises(ConfigError):
        EkfNoise(gyro_noise=0.0)
    with pytest.raises(ConfigError):
        EkfNoise(linear_accel=-1.0)
    with pytest.raises(ConfigError):
        EkfNoise(angular_accel=math.nan)


# -- synthetic run --------------------------------------------------------------------------


@dataclass
class Run:
    """Results of one simulated drive."""

    truth: list[tuple[float, float, float, float]] = field(default_factory=list)  # t, x, y, yaw
    ekf_pose: list[tuple[float, float, float]] = field(default_factory=list)
    odo_pose: list[tuple[float, float, float]] = field(default_factory=list)
    bias_after_standstill: float = math.nan
    slip_gates: list[Gate] = field(default_factory=list)
    other_wheel_gates: list[Gate] = field(default_factory=list)
    gyro_gates: list[Gate] = field(default_factory=list)
    ekf: PlanarEkf | None = None
    odo: WheelOdometry | None = None


def _segments(laps: int = 2) -> list[tuple[float, float, float]]:
    """(v [m/s], w [rad/s], duration [s]): stand, 4 m squares counter-clockwise, stand."""
    turn = (0.0, 0.6, (math.pi / 2) / 0.6)
    side = (0.5, 0.0, 8.0)
    return [(0.0, 0.0, 5.0)] + [side, turn] * (4 * laps) + [(0.0, 0.0, 2.0)]


def simulate(
    right_radius_error: float = 0.015,
    slip: tuple[float, float] | None = (12.0, 0.4),
    gyro_bias: float = 0.01,
    gyro_scale_error: float = 0.002,
    gyro_sigma: float = 0.002,
    seed: int = 42,
    laps: int = 2,
    queue_gyro: bool = False,
) -> Run:
    rng = np.random.default_rng(seed)
    dt = 0.01
    accel, alpha = 1.0, 2.0  # [m/s^2], [rad/s^2]: the chassis' acceleration limits
    run = Run()
    odo = WheelOdometry(PARAMS)
    ekf = PlanarEkf()
    run.ekf, run.odo = ekf, odo
    x = y = yaw = v = w = 0.0
    pos_l = float(2**31 - 40_000)  # counters start near the int32 wrap
    pos_r = float(-(2**31) + 10)
    t = 0.0
    k = 0
    standstill_end = _segments()[0][2]
    for v_cmd, w_cmd, duration in _segments(laps):
        end = t + duration
        while t < end - 1e-9:
            # acceleration-limited command tracking
            v += max(-accel * dt, min(accel * dt, v_cmd - v))
            w += max(-alpha * dt, min(alpha * dt, w_cmd - w))
            vl, vr = v - w * TRACK / 2, v + w * TRACK / 2
            # truth: exact arc over the step
            if abs(w) > 1e-12:
                r = v / w
                x += r * (math.sin(yaw + w * dt) - math.sin(yaw))
                y -= r * (math.cos(yaw + w * dt) - math.cos(yaw))
            else:
                x += v * dt * math.cos(yaw)
                y += v * dt * math.sin(yaw)
            yaw += w * dt
            t = round(t + dt, 9)
            k += 1
            # encoders: the right wheel is bigger than the parameters say, so it turns less
            slipping = slip is not None and slip[0] <= t < slip[0] + slip[1]
            pos_l += (vl + (0.4 if slipping else 0.0)) * dt / MPP
            pos_r += vr * dt / (MPP * (1 + right_radius_error))
            run.truth.append((t, x, y, yaw))
            # gyro at 100 Hz, quantised like ImuGyro.Z
            gz = w * (1 + gyro_scale_error) + gyro_bias + rng.normal(0, gyro_sigma)
            gz = round(gz / GYRO_LSB) * GYRO_LSB
            if queue_gyro:  # as the driver does: fused with the next wheel update
                queued = ekf.add_gyro(gz, t)
                if queued is not None:
                    run.gyro_gates.append(queued)
            else:
                run.gyro_gates.append(ekf.update_gyro(gz, stamp=t))
            # wheels at 50 Hz
            if k % 2 == 0:
                left = (math.floor(pos_l) + 2**31) % 2**32 - 2**31
                right = (math.floor(pos_r) + 2**31) % 2**32 - 2**31
                odo.update(left, right, t)
                if odo.has_baseline and odo.stamp == t:
                    gate = ekf.update_wheels(odo.linear, odo.angular, odo.twist_covariance, stamp=t)
                    in_slip = slip is not None and slip[0] <= t < slip[0] + slip[1] + 0.05
                    (run.slip_gates if in_slip else run.other_wheel_gates).append(gate)
            if abs(t - standstill_end) < 1e-9:
                run.bias_after_standstill = ekf.gyro_bias
            run.ekf_pose.append(ekf.pose)
            run.odo_pose.append((odo.x, odo.y, odo.yaw))
    return run


@pytest.fixture(scope="module", params=[False, True], ids=["per-sample", "queued-gyro"])
def p6_run(request: pytest.FixtureRequest) -> Run:
    return simulate(queue_gyro=request.param)


def _heading_errors(run: Run) -> tuple[np.ndarray, np.ndarray]:
    truth = np.array([normalize_angle(p[3]) for p in run.truth])
    ekf = np.array([p[2] for p in run.ekf_pose])
    odo = np.array([p[2] for p in run.odo_pose])
    wrap = np.vectorize(normalize_angle)
    return np.abs(wrap(ekf - truth)), np.abs(wrap(odo - truth))


def test_bias_is_learned_at_standstill(p6_run: Run) -> None:
    assert p6_run.bias_after_standstill == pytest.approx(0.01, abs=5e-4)
    assert p6_run.ekf is not None
    assert p6_run.ekf.gyro_bias == pytest.approx(0.01, abs=1e-3)  # and held while driving


def test_ekf_heading_beats_wheel_odometry_fivefold(p6_run: Run) -> None:
    ekf_err, odo_err = _heading_errors(p6_run)
    # the wheel odometry is really bad here: slip plus 1.5 % radius error
    assert odo_err[-1] > 0.3
    assert ekf_err[-1] <= odo_err[-1] / 5
    assert ekf_err.max() < 0.05  # [rad] never lost on the way either
    assert ekf_err[-1] < 0.03


def test_ekf_position_beats_wheel_odometry(p6_run: Run) -> None:
    t, x, y, _ = p6_run.truth[-1]
    ex, ey, _ = p6_run.ekf_pose[-1]
    ox, oy, _ = p6_run.odo_pose[-1]
    ekf_err = math.hypot(ex - x, ey - y)
    odo_err = math.hypot(ox - x, oy - y)
    assert t > 80.0
    assert ekf_err < odo_err / 3
    assert ekf_err < 0.5  # [m] after 64 m of driving and two full squares


def test_slip_episode_is_rejected(p6_run: Run) -> None:
    rejected = [g for g in p6_run.slip_gates if g in (Gate.ANGULAR_REJECTED, Gate.REJECTED)]
    assert len(rejected) >= 0.8 * 20  # 0.4 s of slip at 50 Hz
    # outside the slip the wheels are believed (the 1.5 % error is within their covariance)
    others = p6_run.other_wheel_gates
    assert sum(g in (Gate.ACCEPTED, Gate.STANDSTILL) for g in others) >= 0.99 * len(others)
    assert sum(g is Gate.ACCEPTED for g in p6_run.gyro_gates) >= 0.99 * len(p6_run.gyro_gates)


def test_covariance_stays_consistent(p6_run: Run) -> None:
    ekf = p6_run.ekf
    assert ekf is not None
    p = ekf.P
    np.testing.assert_allclose(p, p.T, atol=1e-15)
    assert np.all(np.linalg.eigvalsh(p) > 0)
    # the heading error is inside a few reported sigmas
    ekf_err, _ = _heading_errors(p6_run)
    assert ekf_err[-1] < 4 * math.sqrt(p[YAW, YAW])


def test_ekf_converges_to_truth_without_faults() -> None:
    run = simulate(right_radius_error=0.0, slip=None, gyro_scale_error=0.0, seed=5, laps=1)
    ekf_err, _ = _heading_errors(run)
    assert ekf_err[-1] < 0.01
    _t, x, y, _ = run.truth[-1]
    ex, ey, _ = run.ekf_pose[-1]
    assert math.hypot(ex - x, ey - y) < 0.1
    assert run.ekf is not None
    assert run.ekf.gyro_bias == pytest.approx(0.01, abs=5e-4)
    assert run.ekf.twist == pytest.approx((0.0, 0.0), abs=1e-3)


def _stand_then_drive(still: float, drive: float) -> tuple[float, float, float]:
    """x variance [m^2] once standstill is detected, after ``still`` s of it and after
    ``drive`` s more at 0.5 m/s (wheels 50 Hz, gyro 100 Hz with bias and noise, seeded)."""
    rng = np.random.default_rng(7)
    ekf = PlanarEkf(stamp=0.0)
    var: list[float] = []
    for k in range(1, round(100 * (still + drive)) + 1):
        t = k / 100
        v = 0.5 if t > still else 0.0
        ekf.update_gyro(0.01 + rng.normal(0.0, 2e-3), stamp=t)
        if k % 2 == 0:
            ekf.update_wheels(v, 0.0, stamp=t)
        if k in (100, round(100 * still)):
            assert ekf.is_standstill
            var.append(float(ekf.P[0, 0]))
    var.append(float(ekf.P[0, 0]))
    return var[0], var[1], var[2]


def test_pose_covariance_does_not_grow_at_standstill_but_does_while_driving() -> None:
    start, after_60_s, driven = _stand_then_drive(61.0, 5.0)
    assert after_60_s == pytest.approx(start, rel=1e-6, abs=1e-12)
    assert driven > 2 * start  # moving: the pose uncertainty grows again


# -- the update arithmetic against filterpy and the plain Joseph form -------------------------


def _moving_filter(seed: int = 3) -> PlanarEkf:
    rng = np.random.default_rng(seed)
    ekf = PlanarEkf(stamp=0.0)
    for k in range(1, 60):
        ekf.update_gyro(0.2 + rng.normal(0, 0.01), stamp=0.01 * k)
        if k % 2 == 0:
            ekf.update_wheels(0.5 + rng.normal(0, 0.01), 0.2, stamp=0.01 * k)
    return ekf


def test_update_without_consider_states_is_filterpys() -> None:
    from filterpy.kalman import ExtendedKalmanFilter

    ekf = _moving_filter()
    reference = ExtendedKalmanFilter(dim_x=ekf.kf.dim_x, dim_z=1)
    reference.x, reference.P = ekf.kf.x.copy(), ekf.kf.P.copy()
    h = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 1.0]])
    r = np.array([[3e-6]])
    z = np.array([[0.25]])
    reference.update(z, lambda _x: h, lambda x: h @ x, R=r)
    ekf._apply(z, h, r, ekf._innovation(z, h, r))  # no consider state: a full update
    np.testing.assert_allclose(ekf.kf.x, reference.x, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ekf.kf.P, reference.P, rtol=1e-9, atol=1e-16)
    np.testing.assert_allclose(ekf.kf.K, reference.K, rtol=1e-12)


@pytest.mark.parametrize("consider", [(B,), (0, 1, YAW, B)])
def test_consider_update_is_the_joseph_form_of_the_masked_gain(consider: tuple[int, ...]) -> None:
    ekf = _moving_filter()
    x0, p0 = ekf.kf.x.copy(), ekf.kf.P.copy()
    h = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
    r = np.diag([1e-4, 4e-3])
    z = np.array([[0.52], [0.18]])
    # the textbook Schmidt-Kalman update, written independently
    k = p0 @ h.T @ np.linalg.inv(h @ p0 @ h.T + r)
    k[list(consider), :] = 0.0
    i_kh = np.eye(DIM_X) - k @ h
    p_ref = i_kh @ p0 @ i_kh.T + k @ r @ k.T
    ekf._apply(z, h, r, ekf._innovation(z, h, r), consider=consider)
    np.testing.assert_allclose(ekf.kf.x, x0 + k @ (z - h @ x0), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ekf.kf.P, p_ref, rtol=1e-8, atol=1e-15)
    for i in consider:  # a consider state keeps its value and its own variance
        assert ekf.kf.x[i, 0] == x0[i, 0]
        assert ekf.kf.P[i, i] == p0[i, i]


def test_queued_gyro_does_not_wait_for_wheels_forever() -> None:
    ekf = PlanarEkf(stamp=0.0)
    gates = [ekf.add_gyro(0.1, 0.01 * k) for k in range(1, 12)]
    # samples spanning more than max_step (0.05 s) are fused without the wheels
    assert gates[:6] == [None] * 6 and gates[6] is Gate.ACCEPTED
    assert ekf.stamp == pytest.approx(0.06) and ekf.pending_gyro == 5
    assert ekf.add_gyro(math.nan, 0.12) is Gate.INVALID
    assert ekf.pending_gyro == 5
    ekf.discard_gyro()
    assert ekf.pending_gyro == 0
    x = ekf.x
    ekf.update_wheels(0.0, 0.0)  # nothing queued: only the wheels
    assert ekf.statistics["gyro.accepted"] == 1
    assert not np.array_equal(x, ekf.x)
