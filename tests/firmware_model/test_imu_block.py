"""The IMU noise block works in preallocated buffers and hands the compiled loop its array
directly; these tests pin it bit for bit to the plain numpy form it replaced (kept below as the
reference): the same draws in the same order, the same float operations."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from lowerbase.firmware_model.imu import _BLOCK, _CHUNK, FLICKER_TAUS, ImuModel, _ar1_matrix, _fold
from lowerbase.firmware_model.profile import ImuParams


def reference_block(imu: ImuModel, dt: float, rng: np.random.Generator
                    ) -> tuple[list[list[float]], np.ndarray, np.ndarray]:
    """The block as imu.py computed it before (numpy temporaries, rows as a reversed list):
    (rows, Gauss-Markov states after, free walk after), from ``imu``'s state and ``rng``."""
    n, taus, k = _BLOCK, np.array(FLICKER_TAUS), _BLOCK // _CHUNK
    phi = np.exp(-dt / taus)
    lower = _ar1_matrix(phi, _CHUNK)[:, None]
    decay = (phi[:, None] ** np.arange(1, _CHUNK + 1)[None, :])[:, None, :, None]
    phi_chunk = phi**_CHUNK
    lower_k = _ar1_matrix(phi_chunk, k)
    decay_k = phi_chunk[:, None] ** np.arange(1, k + 1)[None, :]
    drive = np.sqrt(-np.expm1(-2.0 * dt / taus))[:, None] * imu._flicker
    z = rng.standard_normal((len(taus), n, 6)) * drive[:, None, :]
    local = np.matmul(lower, z.reshape(len(taus), k, _CHUNK, 6))
    ends = np.matmul(lower_k, local[:, :, -1, :]) + (decay_k[:, :, None] * imu._gm[:, None, :])
    before = np.concatenate([imu._gm[:, None, :], ends[:, :-1, :]], axis=1)
    gm = (local + decay * before[:, :, None, :]).reshape(len(taus), n, 6)
    free = imu._rw + np.cumsum(rng.standard_normal((n, 6)), axis=0) * (
        imu._walk * math.sqrt(dt))
    white = rng.standard_normal((n, 6)) * imu._white
    rows = np.hstack([gm.sum(axis=0) + _fold(free, imu._bound), white]).tolist()
    rows.reverse()
    return rows, ends[:, -1, :], free[-1]


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize("params", [
    ImuParams(),
    dataclasses.replace(ImuParams(), bias_walk_bound=0.1, seed=9),  # the walk folds often
    dataclasses.replace(ImuParams(), gyro_random_walk=0.0, seed=5),  # bound 0: _fold's path
])
@pytest.mark.parametrize("compiled", [False, True])
def test_blocks_bit_identical_to_the_numpy_form(params: ImuParams, compiled: bool) -> None:
    """Both forms: numpy in buffers, and the compiled end (where every axis is bounded)."""
    if compiled:
        pytest.importorskip("numba")
        from lowerbase.firmware_model.imu_kernel import finish
        assert finish() is not None
    imu = ImuModel(params, np.random.default_rng(params.seed))
    for dt in (0.01, 0.01, 0.01, 0.005, 0.005, 0.01):  # a dt change rebuilds the filters
        mirror = np.random.default_rng()
        mirror.bit_generator.state = imu.rng.bit_generator.state
        rows, gm, rw = reference_block(imu, dt, mirror)
        imu._block(dt, compiled=compiled)
        assert imu._arr.flags.c_contiguous and imu._left == _BLOCK
        assert np.array_equal(bits(imu._arr), bits(np.array(rows)))
        assert np.array_equal(bits(imu._gm), bits(gm))
        assert np.array_equal(bits(imu._rw), bits(rw))
        assert imu.rng.bit_generator.state == mirror.bit_generator.state


def test_samples_and_at_rest_read_the_rows_in_order() -> None:
    """sample() takes the rows last first (as the list's pop did), across blocks; at_rest
    continues the same sequence; a block half used by sample() is finished by at_rest."""
    p = ImuParams()
    imu = ImuModel(p, np.random.default_rng(3))
    ref = ImuModel(p, np.random.default_rng(3))
    dt = 1.0 / p.rate_hz
    expected: list[list[float]] = []
    for _ in range(4):
        rows, ref._gm, ref._rw = reference_block(ref, dt, ref.rng)
        expected.extend(reversed(rows))
    gs, as_ = 1.0 + p.gyro_scale_error, 1.0 + p.accel_scale_error
    gt, at = imu.gyro_turn_on, imu.accel_turn_on
    for j in range(_BLOCK + 100):
        z = expected[j]
        gyro, accel = imu.sample((0.1, 0.0, 0.2), (0.3, 0.0, 0.0), dt)
        assert gyro[2] == gs * 0.2 + (gt[2] + z[2]) + z[8]
        assert accel[0] == as_ * 0.3 + (at[0] + z[3]) + z[9]
        assert imu.gyro_bias == [gt[i] + z[i] for i in range(3)]
    rest = imu.at_rest(2 * _BLOCK, dt)
    zs = np.array(expected[_BLOCK + 100:3 * _BLOCK + 100])
    turn_on = np.array(gt + at)
    true = np.array([0.0, 0.0, 0.0, 0.0, 0.0, p.gravity * (1.0 + p.accel_scale_error)])
    assert np.array_equal(bits(rest), bits(true + turn_on + zs[:, :6] + zs[:, 6:]))
    gyro, _ = imu.sample((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), dt)
    z0 = expected[3 * _BLOCK + 100]
    assert gyro[0] == (gt[0] + z0[0]) + z0[6]


def test_flicker_sigma_is_computed_once_per_parameters() -> None:
    """A boot makes a new ImuModel: the flicker bisection (~30 ms) is kept per arguments,
    and the kept value is the computed one."""
    from lowerbase.firmware_model.imu import DEG, DEG_PER_HOUR, flicker_sigma

    p = dataclasses.replace(ImuParams(), gyro_bias_instability=4.25)
    first = ImuModel(p, np.random.default_rng(1))
    hits = flicker_sigma.cache_info().hits
    second = ImuModel(p, np.random.default_rng(1))
    assert flicker_sigma.cache_info().hits == hits + 2  # gyro and accel
    assert np.array_equal(bits(first._flicker), bits(second._flicker))
    fresh = flicker_sigma.__wrapped__(p.gyro_noise_density * DEG,
                                      p.gyro_bias_instability * DEG_PER_HOUR,
                                      p.gyro_random_walk, "imu.gyro_bias_instability")
    assert first._flicker[0] == fresh
