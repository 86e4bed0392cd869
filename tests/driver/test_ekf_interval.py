"""PlanarEkf's intervals: the rates measured over a wheel cycle drive the pose over that cycle.

Checked against closed forms on a simulated clock (gyro at 100 Hz, wheels at 50 Hz, in the
driver's order: at a common stamp the wheel frame comes first): a constant-rate turn from
standstill, a linear ramp of the turn rate, and the trapezoid weights against numerical
integration. Predicting with the previous cycle's rate lags the heading by a cycle for as long
as the turn lasts (0.57 deg at 0.5 rad/s): these tests fail on that.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from lowerbase.driver.ekf import B, EkfNoise, PlanarEkf, V, interval_weights

GYRO_DT = 0.01  #: [s] 100 Hz
BIAS = 0.01  #: [rad/s] z-gyro bias, known to the filter


def _driving(v: float) -> PlanarEkf:
    """A filter at the origin heading east at ``v`` [m/s], the gyro bias known, at t = 0."""
    ekf = PlanarEkf(stamp=0.0)
    ekf.reset(gyro_bias=BIAS)
    ekf.kf.x[V, 0] = v
    ekf.kf.P[V, V] = ekf.kf.P[B, B] = 1e-8
    return ekf


def _drive(ekf: PlanarEkf, rate: Callable[[float], float],
           mean_twist: Callable[[float, float], tuple[float, float]], seconds: float,
           queue_gyro: bool) -> list[tuple[float, tuple[float, float, float]]]:
    """Feed exact gyro samples ``rate(t) + BIAS`` at 100 Hz and the wheels' twists (the means
    over their cycle) at 50 Hz; returns (stamp, EKF pose) after each wheel update.

    Queued (the driver): at a common stamp the wheel frame comes first. Per sample: each gyro
    sample is fused at once, so it must come first, else the wheels' interval has no gyro."""
    out = []
    for k in range(1, round(seconds / GYRO_DT) + 1):
        t = round(k * GYRO_DT, 9)
        if not queue_gyro:
            ekf.update_gyro(rate(t) + BIAS, stamp=t)
        if k % 2 == 0:
            ekf.update_wheels(*mean_twist(t - 2 * GYRO_DT, t), stamp=t)
            out.append((t, ekf.pose))
        if queue_gyro:
            ekf.add_gyro(rate(t) + BIAS, t)
    return out


@pytest.mark.parametrize("queue_gyro", [True, False], ids=["queued-gyro", "per-sample"])
def test_a_constant_rate_turn_follows_the_closed_form(queue_gyro: bool) -> None:
    """Straight at 0.4 m/s, then from t_s on a constant 0.5 rad/s turn (an arc of 0.8 m
    radius); the rate steps between two gyro samples, as it may anywhere."""
    v, w, ts = 0.4, 0.5, 1.005

    def turning(a: float, b: float) -> float:  # the part of [a, b] after t_s
        return max(0.0, b - max(a, ts)) / (b - a)

    poses = _drive(_driving(v), lambda t: w if t > ts else 0.0,
                   lambda a, b: (v, w * turning(a, b)), 5.0, queue_gyro)
    yaw_err, pos_err = [], []
    for t, (x, y, yaw) in poses:
        th = w * max(0.0, t - ts)
        truth = (v * min(t, ts) + v / w * math.sin(th), v / w * (1.0 - math.cos(th)))
        yaw_err.append(abs(math.remainder(yaw - th, math.tau)))
        pos_err.append(math.hypot(x - truth[0], y - truth[1]))
    assert len(poses) == 250
    # one wheel cycle of lag would be w * 20 ms = 0.57 deg, and 4 mm after a quarter turn
    assert math.degrees(max(yaw_err)) < 0.01
    assert max(pos_err) < 2e-4


def test_a_ramp_of_the_turn_rate_sampled_at_both_ends_is_integrated_exactly() -> None:
    """rate(t) = c (t - t0): the heading is c (t - t0)^2 / 2. With a gyro sample at each
    interval's end (fed before the wheels here), the trapezoid mean is exact."""
    c, t0 = 0.5, 1.0  # [rad/s^2], [s]
    ekf = _driving(0.0)
    errors = []
    for k in range(1, round(2.0 / GYRO_DT) + 1):
        t = round(k * GYRO_DT, 9)
        r = c * max(0.0, t - t0)
        ekf.add_gyro(r + BIAS, t)
        if k % 2 == 0:
            a = t - 2 * GYRO_DT
            mean = c * (max(0.0, t - t0) ** 2 - max(0.0, a - t0) ** 2) / 2 / (t - a)
            ekf.update_wheels(0.0, mean, stamp=t)  # a turn in place
            if t > t0:
                errors.append(abs(ekf.pose[2] - c * (t - t0) ** 2 / 2))
    # the previous cycle's rate would lag by c * t * 20 ms: 0.57 deg after 1 s
    assert math.degrees(max(errors)) < 0.01


def test_interval_weights_are_the_trapezoid_of_the_interpolated_rate() -> None:
    rng = np.random.default_rng(5)
    for _ in range(50):
        times = np.sort(rng.uniform(0.0, 0.05, size=int(rng.integers(1, 6))))
        rates = rng.normal(size=len(times))
        t0, t1 = sorted(rng.uniform(-0.01, 0.06, size=2))
        w = interval_weights(list(times), float(t0), float(t1))
        assert w.sum() == pytest.approx(1.0)
        dense = np.linspace(t0, t1, 20001)
        # np.interp holds the end values outside the samples, as the weights assume
        expected = np.trapezoid(np.interp(dense, times, rates), dense) / (t1 - t0)
        assert float(w @ rates) == pytest.approx(expected, abs=1e-6)
    assert interval_weights([0.0, 0.01], 0.0, 0.02) == pytest.approx([0.25, 0.75])
    assert interval_weights([0.1, 0.2], 0.5, 0.5) == pytest.approx([0.5, 0.5])  # no interval
    with pytest.raises(ValueError):
        interval_weights([], 0.0, 1.0)


def test_queued_gyro_samples_are_one_measurement_of_the_interval_mean() -> None:
    """Two samples queued in the driver's order, with the last sample fused before: one gyro
    measurement, z = 0.25 g(t) + 0.5 g(t+10 ms) + 0.25 g(t+20 ms), sigma^2 sum(w^2)."""
    ekf = PlanarEkf()
    seen: list[tuple[float, float]] = []
    original = ekf._gyro_mean

    def spy(span):  # type: ignore[no-untyped-def]
        seen.append(original(span))
        return seen[-1]

    ekf._gyro_mean = spy  # type: ignore[method-assign]
    ekf.update_gyro(0.20, stamp=1.00)  # the first stamp: no interval, fused as it is
    assert seen == [(0.20, EkfNoise().gyro_noise)]
    assert ekf.add_gyro(0.21, 1.01) is None and ekf.add_gyro(0.23, 1.02) is None
    assert ekf.pending_gyro == 2 and len(seen) == 1
    ekf.update_wheels(0.5, 0.2, stamp=1.02)
    assert ekf.pending_gyro == 0
    assert seen[1][0] == pytest.approx(0.25 * 0.20 + 0.5 * 0.21 + 0.25 * 0.23)
    assert seen[1][1] == pytest.approx(EkfNoise().gyro_noise * math.sqrt(0.375))
    assert ekf.statistics["gyro.accepted"] == 2


def test_the_three_sample_mean_is_the_general_one_bit_for_bit() -> None:
    """interval_mean3 (the driver's cycle written out) against interval_weight_list and the
    sums _gyro_mean makes: samples inside, straddling and outside the interval, repeated
    times, an empty interval."""
    from lowerbase.driver.ekf_model import interval_mean3, interval_weight_list

    rng = np.random.default_rng(3)
    cases = 0
    for _ in range(4000):
        t0 = float(rng.uniform(0.0, 100.0))
        t1 = t0 + float(rng.choice([0.0, 0.02, rng.uniform(-0.01, 0.05)]))
        times = sorted(float(t0 + rng.choice([-0.03, 0.0, 0.01, 0.02, 0.04,
                                              rng.uniform(-0.03, 0.05)])) for _ in range(3))
        rates = [float(r) for r in rng.normal(0.0, 1.0, 3)]
        weights = interval_weight_list(times, t0, t1)
        mean = squares = 0.0
        for w_i, r_i in zip(weights, rates, strict=True):
            mean += w_i * r_i
            squares += w_i * w_i
        got = interval_mean3(times, rates, t0, t1)
        assert (got[0].hex(), got[1].hex()) == (mean.hex(), squares.hex()), (times, t0, t1)
        cases += 1
    assert cases == 4000
