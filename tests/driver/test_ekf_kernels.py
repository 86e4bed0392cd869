"""The EKF's compiled cycle arithmetic (lowerbase/driver/ekf_kernels.py) against the numpy
forms it replaced (lowerbase/driver/ekf_model.py: innovation, apply_update, motion_model,
motion_jacobian, slip_noise), on filters in the states the driver meets. The two sum the
products in different orders (OpenBLAS fuses multiply-adds), so they agree to rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.driver.ekf import B, PlanarEkf
from lowerbase.driver.ekf_kernels import _product, _product_t, drive, measure
from lowerbase.driver.ekf_model import (
    DIM_X,
    H_GYRO,
    H_TWIST,
    H_V,
    WHEEL_CONSIDER,
    EkfNoise,
    apply_update,
    innovation,
    motion_jacobian,
    motion_model,
    rate_noise,
    slip_noise,
)


def _filter(seed: int) -> PlanarEkf:
    rng = np.random.default_rng(seed)
    ekf = PlanarEkf(stamp=0.0)
    for k in range(1, 80):
        ekf.update_gyro(0.3 + rng.normal(0, 0.01), stamp=0.01 * k)
        if k % 2 == 0:
            ekf.update_wheels(0.6 + rng.normal(0, 0.01), 0.3, stamp=0.01 * k)
    return ekf


def _keep(consider: tuple[int, ...]) -> np.ndarray:
    return np.array([0 if i in consider else 1 for i in range(DIM_X)], dtype=np.uint8)


def _run(ekf: PlanarEkf, z: np.ndarray, h: np.ndarray, r: np.ndarray,
         consider: tuple[int, ...], gate: float | None
         ) -> tuple[float, bool, np.ndarray, np.ndarray, np.ndarray]:
    m = len(h)
    y, s, si, k = np.empty((m, 1)), np.empty((m, m)), np.empty((m, m)), np.empty((DIM_X, m))
    d2, applied = measure(ekf.kf.x, ekf.kf.P, h, z, r, _keep(consider), gate is not None,
                          0.0 if gate is None else gate, y, s, si, k)
    return d2, applied, y, s, k


CASES = [
    (H_TWIST, np.array([[0.58], [0.33]]), np.diag([1e-4, 6.4e-3]), WHEEL_CONSIDER),
    (H_GYRO, np.array([[0.31]]), np.array([[4e-6]]), (B,)),
    (H_GYRO, np.array([[0.29]]), np.array([[4e-6]]), ()),
    (H_V, np.array([[0.61]]), np.array([[1e-2]]), WHEEL_CONSIDER),
]


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize(("h", "z", "r", "consider"), CASES)
def test_measure_is_innovation_then_apply_update(
        seed: int, h: np.ndarray, z: np.ndarray, r: np.ndarray,
        consider: tuple[int, ...]) -> None:
    ekf, ref = _filter(seed), _filter(seed)
    inn = innovation(ref.kf, z, h, r)
    apply_update(ref.kf, z, inn, consider)
    x0, p0 = ekf.kf.x.copy(), ekf.kf.P.copy()
    d2, applied, y, s, k = _run(ekf, z, h, r, consider, gate=None)
    assert applied
    assert d2 == pytest.approx(inn.d2, rel=1e-12)
    np.testing.assert_allclose(y, inn.y, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(s, inn.s, rtol=1e-12)
    np.testing.assert_allclose(k, ref.kf.K, rtol=1e-10, atol=1e-18)
    np.testing.assert_allclose(ekf.kf.x, ref.kf.x, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ekf.kf.P, ref.kf.P, rtol=1e-9, atol=1e-16)
    assert np.array_equal(ekf.kf.P, ekf.kf.P.T)
    for i in consider:  # a consider state keeps its value and its block of P, bit for bit
        assert ekf.kf.x[i, 0] == x0[i, 0]
        for j in consider:
            assert ekf.kf.P[i, j] == p0[i, j]


def test_a_measurement_outside_its_gate_changes_nothing() -> None:
    ekf = _filter(3)
    x0, p0 = ekf.kf.x.copy(), ekf.kf.P.copy()
    z = np.array([[5.0], [-3.0]])  # far off: well outside the 2-dof gate
    d2, applied, _, _, k = _run(ekf, z, H_TWIST, np.diag([1e-4, 6.4e-3]), WHEEL_CONSIDER,
                                gate=EkfNoise().gate_2dof)
    assert not applied and d2 > EkfNoise().gate_2dof
    assert np.array_equal(ekf.kf.x, x0) and np.array_equal(ekf.kf.P, p0)
    assert not k.any()


@pytest.mark.parametrize(("dt", "frozen"), [(0.02, False), (0.12, False), (0.02, True)])
def test_drive_is_the_stepped_motion_model(dt: float, frozen: bool) -> None:
    ekf, noise = _filter(4), EkfNoise()
    x, p = ekf.kf.x.copy(), ekf.kf.P.copy()
    steps = max(1, math.ceil(dt / noise.max_step))  # 0.12 s: three steps of 0.04 s
    h = dt / steps
    for _ in range(steps):
        if not frozen:
            f = motion_jacobian(x, h)
            p = f @ p @ f.T + slip_noise(x, h, noise)
        x = motion_model(x, h)
    p = 0.5 * (p + p.T)
    p0 = ekf.kf.P.copy()
    drive(ekf.kf.x, ekf.kf.P, dt, noise.max_step, frozen, noise.lateral_slip**2)
    np.testing.assert_allclose(ekf.kf.x, x, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(ekf.kf.P, p, rtol=1e-10, atol=1e-18)
    if frozen:  # at standstill the covariance stays as it was
        assert np.array_equal(ekf.kf.P, p0)


@pytest.mark.parametrize("bias_considered", [True, False])
def test_wheel_cycle_is_gyro_then_wheels_then_drive(bias_considered: bool) -> None:
    """The fused cycle does exactly (bit for bit) what its steps do one by one: the rates'
    process noise, the gyro, the wheels, the drive."""
    from lowerbase.driver.ekf_kernels import CycleWorkspace, wheel_cycle

    ekf, ref, noise = _filter(5), _filter(5), EkfNoise()
    r = np.diag([1e-4, 6.4e-3])
    ws = CycleWorkspace()
    q = np.array([noise.linear_accel**2, noise.angular_accel**2, noise.gyro_bias_walk**2])
    _, d2, applied = wheel_cycle(ekf.kf.x, ekf.kf.P, ws.data, r, True, 0.31, 4e-6,
                                 bias_considered, 0.58, 0.3, noise.gate_2dof, 0.02,
                                 noise.max_step, False, noise.lateral_slip**2, q)
    ref.kf.P += rate_noise(0.02, noise)
    x_prior, p_prior = ref.kf.x.copy(), ref.kf.P.copy()
    _run(ref, np.array([[0.31]]), H_GYRO, np.array([[4e-6]]),
         (B,) if bias_considered else (), None)
    d2_ref, applied_ref, y, s, k = _run(ref, np.array([[0.58], [0.3]]), H_TWIST, r,
                                        WHEEL_CONSIDER, noise.gate_2dof)
    x_post = ref.kf.x.copy()
    drive(ref.kf.x, ref.kf.P, 0.02, noise.max_step, False, noise.lateral_slip**2)
    assert applied and applied_ref and d2 == d2_ref
    assert np.array_equal(ekf.kf.x, ref.kf.x) and np.array_equal(ekf.kf.P, ref.kf.P)
    wy, wsv, _, wk, wz = ws.wheel
    assert np.array_equal(wy, y) and np.array_equal(wsv, s) and np.array_equal(wk, k)
    assert wz.ravel().tolist() == [0.58, 0.3]
    assert np.array_equal(ws.post[0], x_post)  # after the update, before the drive
    assert np.array_equal(ws.prior[0], x_prior) and np.array_equal(ws.prior[1], p_prior)


def test_the_filter_fails_over_to_the_gate_outcomes_when_the_wheels_fail_the_gate() -> None:
    ekf = _filter(6)
    t = ekf.stamp
    assert t is not None
    x0 = ekf.kf.x.copy()
    ekf.add_gyro(0.3, t + 0.01)
    ekf.add_gyro(0.3, t + 0.02)
    # the wheels claim a yaw rate the gyro contradicts: a slipping wheel
    from lowerbase.driver.ekf import Gate

    assert ekf.update_wheels(0.6, 1.5, stamp=t + 0.02) is Gate.ANGULAR_REJECTED
    assert ekf.statistics["gyro.accepted"] >= 1 and ekf.mahalanobis_sq > EkfNoise().gate_2dof
    assert ekf.kf.K.shape == (DIM_X, 1)  # the speed-only update's gain
    assert ekf.kf.x[0, 0] > x0[0, 0]  # the pose was driven over the cycle all the same


@pytest.mark.parametrize("shape", [(6, 6, 6), (6, 2, 2), (2, 6, 1), (1, 6, 6)])
def test_the_products_sum_in_index_order(shape: tuple[int, int, int]) -> None:
    """Every fixed-order product of the kernels: each entry ``0.0 + a0*b0 + a1*b1 + ...`` in
    index order, bit for bit (what makes the filter's bits the same on every CPU)."""
    n, k, m = shape
    rng = np.random.default_rng(7)
    a, b = rng.normal(size=(n, k)), rng.normal(size=(k, m))

    def plain(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        out = np.empty((a.shape[0], b.shape[1]))
        for i in range(a.shape[0]):
            for j in range(b.shape[1]):
                acc = 0.0
                for q in range(a.shape[1]):
                    acc += float(a[i, q]) * float(b[q, j])
                out[i, j] = acc
        return out

    out = np.empty((n, m))
    _product(a, b, out)
    assert out.tobytes() == plain(a, b).tobytes()
    out_t = np.empty((n, m))
    _product_t(a, np.ascontiguousarray(b.T), out_t)
    assert out_t.tobytes() == plain(a, b).tobytes()
