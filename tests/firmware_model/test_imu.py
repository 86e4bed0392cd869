"""IMU model: exact ideal sensor, noise statistics, bounded bias walk, faults."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from lowerbase.errors import ConfigError
from lowerbase.firmware_model.imu import DEG, ImuModel, accel_sigma
from lowerbase.firmware_model.imu import gyro_sigma as gyro_sigma_of
from lowerbase.firmware_model.profile import STANDARD_GRAVITY, ImuParams

IDEAL = ImuParams(noise=False)
# Noise on, but only the white noise: no turn-on bias, flicker, walk or scale error.
WHITE = ImuParams(
    gyro_random_walk=0.0,
    accel_random_walk=0.0,
    gyro_bias_instability=0.0,
    accel_bias_instability=0.0,
    gyro_turn_on_bias=0.0,
    accel_turn_on_bias=0.0,
    gyro_scale_error=0.0,
    accel_scale_error=0.0,
)


def test_ideal_sensor_is_exact_with_gravity_on_z() -> None:
    imu = ImuModel(IDEAL)
    gyro, accel = imu.sample((0.1, -0.2, 0.3), (0.5, -0.25, 0.0), 0.01)
    assert gyro == (0.1, -0.2, 0.3)
    assert accel == (0.5, -0.25, STANDARD_GRAVITY)
    assert imu.sample((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.01) == ((0, 0, 0), (0, 0, 9.80665))


def test_white_noise_sigma_is_density_times_sqrt_rate() -> None:
    imu = ImuModel(WHITE, np.random.default_rng(1))
    samples = np.array([sum(imu.sample((0, 0, 0.5), (0, 0, 0), 0.01), ()) for _ in range(20_000)])
    gyro_sigma = 0.0028 * math.pi / 180 * math.sqrt(100)  # 4.89e-4 rad/s
    accel_sigma_ = 70e-6 * 9.80665 * math.sqrt(100)  # 6.86e-3 m/s^2
    assert gyro_sigma_of(WHITE) == pytest.approx(gyro_sigma)
    assert accel_sigma(WHITE) == pytest.approx(accel_sigma_)
    np.testing.assert_allclose(samples[:, :3].std(axis=0), gyro_sigma, rtol=0.1)
    np.testing.assert_allclose(samples[:, 3:].std(axis=0), accel_sigma_, rtol=0.1)
    np.testing.assert_allclose(samples[:, :3].mean(axis=0), [0, 0, 0.5], atol=5 * gyro_sigma / 100)
    assert samples[:, 5].mean() == pytest.approx(STANDARD_GRAVITY, abs=5 * accel_sigma_ / 100)


def test_same_seed_same_samples() -> None:
    a, b = ImuModel(ImuParams(seed=3)), ImuModel(ImuParams(seed=3))
    for _ in range(10):
        assert a.sample((0, 0, 0), (0, 0, 0), 0.01) == b.sample((0, 0, 0), (0, 0, 0), 0.01)
    assert ImuModel(ImuParams(seed=4)).gyro_turn_on != a.gyro_turn_on


def test_bias_random_walk_stays_within_its_bound() -> None:
    params = replace(WHITE, gyro_random_walk=1e-4, accel_random_walk=1e-3, gyro_turn_on_bias=1.0,
                     bias_walk_bound=0.1)
    imu = ImuModel(params, np.random.default_rng(2))
    g_bound = 0.1 * 1e-4 * 60.0  # bias_walk_bound x the walk's one-hour sigma (K x 60 s^0.5)
    a_bound = 0.1 * 1e-3 * 60.0  # 6 K, reached within the 200 s (sigma 14 K)
    g_dev, a_dev = [], []
    for _ in range(20_000):
        imu.sample((0, 0, 0), (0, 0, 0), 0.01)
        g_dev.append(np.subtract(imu.gyro_bias, imu.gyro_turn_on))
        a_dev.append(np.subtract(imu.accel_bias, imu.accel_turn_on))
    g, a = np.abs(g_dev), np.abs(a_dev)
    assert g.max() <= g_bound and a.max() <= a_bound
    assert g.max() > 0.5 * g_bound and a.max() > 0.5 * a_bound  # the walk does move
    assert np.abs(imu.gyro_turn_on).max() > 0.1 * DEG  # the turn-on bias was drawn


def test_scale_error_and_turn_on_bias_enter_the_output() -> None:
    params = replace(WHITE, gyro_noise_density=0.0, accel_noise_density=0.0, gyro_scale_error=0.01)
    params = replace(params, gyro_turn_on_bias=0.5, accel_scale_error=-0.02)
    imu = ImuModel(params)
    gyro, accel = imu.sample((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.01)
    assert gyro[2] == pytest.approx(1.01 + imu.gyro_turn_on[2])
    assert accel[2] == pytest.approx(0.98 * STANDARD_GRAVITY)


def test_bias_step_freeze_and_saturation() -> None:
    imu = ImuModel(IDEAL)
    imu.bias_step(gyro=(0.0, 0.0, 0.02))
    gyro, _ = imu.sample((0.0, 0.0, 0.1), (0.0, 0.0, 0.0), 0.01)
    assert gyro[2] == pytest.approx(0.12)
    imu.freeze()
    assert imu.sample((0.0, 0.0, 0.7), (3.0, 0.0, 0.0), 0.01) == (gyro, (0.0, 0.0, 9.80665))
    imu.freeze(False)
    gyro, accel = imu.sample((0.0, 0.0, 100.0), (0.0, 0.0, 500.0), 0.01)
    assert gyro[2] == pytest.approx(2000 * DEG)
    assert accel[2] == pytest.approx(16 * STANDARD_GRAVITY)


def test_an_instability_below_the_white_and_walk_floor_is_one_clear_error() -> None:
    with pytest.raises(ConfigError, match=r"imu.gyro_bias_instability = 0.5 is below the Allan"):
        ImuParams(gyro_bias_instability=0.5, gyro_random_walk=1e-5)
    ImuParams(gyro_bias_instability=0.0, gyro_random_walk=1e-5)  # 0: no flicker term


def test_bias_blocks_are_the_gauss_markov_recursion_sample_by_sample() -> None:
    """The chunked matrix form of the flicker terms equals x[j] = phi x[j-1] + drive z[j],
    run one sample at a time from the same state and the same normal draws, over three
    blocks (so the carry between blocks is covered too)."""
    from lowerbase.firmware_model.imu import FLICKER_TAUS, _fold

    imu = ImuModel(ImuParams(), np.random.default_rng(11))
    dt = 1.0 / imu.params.rate_hz
    taus = np.array(FLICKER_TAUS)
    phi = np.exp(-dt / taus)[:, None]
    drive = np.sqrt(-np.expm1(-2.0 * dt / taus))[:, None] * imu._flicker
    x, rw = imu._gm.copy(), imu._rw.copy()
    for _ in range(3):
        mirror = np.random.default_rng()
        mirror.bit_generator.state = imu.rng.bit_generator.state
        imu._block(dt)
        rows = imu._arr[::-1]
        z = mirror.standard_normal((len(taus), len(rows), 6)) * drive[:, None, :]
        walk = rw + np.cumsum(mirror.standard_normal((len(rows), 6)), axis=0) * (
            imu._walk * math.sqrt(dt))
        rw = walk[-1]
        expected = np.empty((len(rows), 6))
        for j in range(len(rows)):
            x = phi * x + z[:, j, :]
            expected[j] = x.sum(axis=0)
        expected += _fold(walk, imu._bound)
        scale = np.abs(expected).max(axis=0)
        assert np.all(np.abs(rows[:, :6] - expected) <= 1e-12 * scale)
        assert np.allclose(imu._gm, x, rtol=1e-12, atol=0.0)
