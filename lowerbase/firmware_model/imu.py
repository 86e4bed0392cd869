"""6-axis MEMS IMU model: the datasheet noise terms as an Allan analysis reads them back.

Per axis: ``out = (1 + scale) * true + turn_on + flicker + walk + white``:

- white noise, discrete sigma ``density * sqrt(rate_hz)`` (Allan: density / sqrt(tau));
- bias instability as flicker: a sum of first-order Gauss-Markov processes with correlation
  times every half decade from 0.3 s to 30000 s (ripple about 4 %), scaled so that the
  MINIMUM of the model's Allan deviation (white + flicker + walk) is 0.664 x the datasheet
  bias instability, which is how a datasheet figure is read (IEEE 952);
- rate random walk ``b += random_walk * sqrt(dt) * N(0, 1)`` (Allan: K sqrt(tau / 3)), which
  reflects at +-``bias_walk_bound`` x its one-hour sigma (K x 60 s^0.5) so it stays bounded;
- turn-on bias drawn once per boot; scale error; saturation.

The bias processes are generated in blocks of samples with numpy (an hour at 100 Hz takes well
under a second). The accelerometer measures specific force: the base acceleration plus
``gravity`` on +z. With ``noise = false`` the sensor is ideal and outputs are exact; the fault
hooks (:meth:`ImuModel.bias_step`, :meth:`ImuModel.freeze`) work either way.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from lowerbase.firmware_model.allan import (
    DEG,
    DEG_PER_HOUR,
    FLICKER_TAUS,
    MICRO_G,
    STANDARD_GRAVITY,
    flicker_sigma,
)
from lowerbase.firmware_model.profile import ImuParams

Vec3 = tuple[float, float, float]

def gyro_sigma(params: ImuParams) -> float:
    """Discrete white-noise sigma of a gyro sample [rad/s]: density * sqrt(rate_hz)."""
    return params.gyro_noise_density * DEG * math.sqrt(params.rate_hz)


def accel_sigma(params: ImuParams) -> float:
    """Discrete white-noise sigma of an accel sample [m/s^2]: density * sqrt(rate_hz)."""
    return params.accel_noise_density * MICRO_G * math.sqrt(params.rate_hz)


_BLOCK = 256  # samples of bias and noise generated at once
_CHUNK = 16  # samples per inner chunk of the Gauss-Markov recursion (_BLOCK is a multiple)


def _ar1_matrix(phi: np.ndarray, n: int) -> np.ndarray:
    """Per coefficient ``phi[i]`` the n x n matrix L with L[j, m] = phi[i]**(j - m) for
    j >= m, else 0: ``L @ z`` is the AR(1) recursion ``x[j] = phi x[j-1] + z[j]`` from 0."""
    lag = np.arange(n)[:, None] - np.arange(n)[None, :]
    return np.where(lag >= 0, phi[:, None, None] ** np.maximum(lag, 0), 0.0)


def _fold(x: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """``x`` reflected into [-bound, bound] (a triangle wave of period 4 bound; bound 0 -> 0)."""
    b = np.where(bound > 0.0, bound, 1.0)
    y = np.mod(x + b, 4.0 * b)
    return np.where(bound > 0.0, np.where(y < 2.0 * b, y, 4.0 * b - y) - b, 0.0)


def _compiled_finish() -> Any:
    """:func:`.imu_kernel.finish_block` compiled, or None (imported only when asked for)."""
    try:
        from lowerbase.firmware_model.imu_kernel import finish
    except ImportError:  # no numba: the numpy form
        return None
    return finish()


class ImuModel:
    """Stateful IMU: call :meth:`sample` once per output sample (nominally at ``rate_hz``).

    The six bias processes and white noises come from the numpy generator in blocks, so a seed
    gives the same sequence on every machine; samples are assumed evenly spaced by the ``dt``
    of the call that starts a block.
    """

    def __init__(self, params: ImuParams, rng: np.random.Generator | None = None) -> None:
        self.params = params
        self.rng = rng if rng is not None else np.random.default_rng(params.seed)
        if params.noise:
            g0 = self.rng.normal(0.0, params.gyro_turn_on_bias * DEG, 3)
            a0 = self.rng.normal(0.0, params.accel_turn_on_bias * 1e3 * MICRO_G, 3)
            self.gyro_turn_on: list[float] = [float(x) for x in g0]
            self.accel_turn_on: list[float] = [float(x) for x in a0]
        else:
            self.gyro_turn_on, self.accel_turn_on = [0.0] * 3, [0.0] * 3
        self.gyro_bias = list(self.gyro_turn_on)  # [rad/s] turn-on + flicker + walk, now
        self.accel_bias = list(self.accel_turn_on)  # [m/s^2] turn-on + flicker + walk, now
        self.gyro_fault = [0.0, 0.0, 0.0]  # [rad/s] injected bias steps
        self.accel_fault = [0.0, 0.0, 0.0]  # [m/s^2] injected bias steps
        self.frozen = False
        self._last: tuple[Vec3, Vec3] = ((0.0, 0.0, 0.0), (0.0, 0.0, params.gravity))
        p = params
        g_n, a_n = p.gyro_noise_density * DEG, p.accel_noise_density * MICRO_G
        self._white = np.array([gyro_sigma(p)] * 3 + [accel_sigma(p)] * 3)
        self._walk = np.array([p.gyro_random_walk] * 3 + [p.accel_random_walk] * 3)
        self._flicker = np.array(
            [flicker_sigma(g_n, p.gyro_bias_instability * DEG_PER_HOUR, p.gyro_random_walk,
                           "imu.gyro_bias_instability")] * 3
            + [flicker_sigma(a_n, p.accel_bias_instability * MICRO_G, p.accel_random_walk,
                             "imu.accel_bias_instability")] * 3) if p.noise else np.zeros(6)
        self._bound = p.bias_walk_bound * self._walk * 60.0  # one-hour sigma x bound
        n_gm = len(FLICKER_TAUS)
        # stationary start: each Gauss-Markov term drawn from its steady-state distribution
        self._gm = self.rng.standard_normal((n_gm, 6)) * self._flicker if p.noise else np.zeros(
            (n_gm, 6))
        self._rw = np.zeros(6)  # the free (unreflected) walk
        self._filter_dt = -1.0
        self._lower: np.ndarray = np.zeros(0)
        self._decay: np.ndarray = np.zeros(0)
        self._drive: np.ndarray = np.zeros(0)
        self._lower_k: np.ndarray = np.zeros(0)
        self._decay_k: np.ndarray = np.zeros(0)
        self._limits = (p.gyro_full_scale * DEG, p.accel_full_scale * STANDARD_GRAVITY)
        # the noise block: _BLOCK rows of 6 biases + 6 white noises, the LAST row first (row
        # ``_left - 1`` is the next sample's; the compiled loop reads the array as it is)
        self._arr: np.ndarray = np.zeros((0, 12))
        self._left = 0  # rows of _arr not yet used
        self._list: list[list[float]] | None = None  # _arr.tolist(), made when Python samples
        self._walk_dt: np.ndarray = np.zeros(6)
        self._decay_flat: np.ndarray = np.zeros(0)
        self._fold_b: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        if bool(np.all(self._bound > 0.0)):  # _fold's constants (every axis bounded)
            self._fold_b = (self._bound, 4.0 * self._bound, 2.0 * self._bound)
        n_terms = len(FLICKER_TAUS)
        self._z = np.empty((n_terms, _BLOCK, 6))  # buffers _block draws and works into
        self._tmp = np.empty((n_terms, _BLOCK // _CHUNK, _CHUNK, 6))
        self._local = np.empty((n_terms, _BLOCK // _CHUNK, _CHUNK, 6))
        self._free = np.empty((_BLOCK, 6))
        self._white_z = np.empty((_BLOCK, 6))

    def bias_step(self, gyro: Vec3 = (0.0, 0.0, 0.0), accel: Vec3 = (0.0, 0.0, 0.0)) -> None:
        """Fault: add a bias step [rad/s] to the gyro and [m/s^2] to the accelerometer."""
        for i in range(3):
            self.gyro_fault[i] += float(gyro[i])
            self.accel_fault[i] += float(accel[i])

    def freeze(self, on: bool = True) -> None:
        """Fault: while frozen, every sample repeats the last one (the model keeps running)."""
        self.frozen = on

    def _block(self, dt: float, compiled: bool = False) -> None:
        """The next _BLOCK samples of bias (flicker + walk) and white noise, all six axes.

        Each Gauss-Markov term is the exact AR(1) recursion, evaluated in two levels of
        lower-triangular matrix products: within chunks of _CHUNK samples from a zero start,
        then the chunk-end states (the same recursion with phi^_CHUNK), whose decay is added
        back into each chunk. That is the one-matrix form's arithmetic up to rounding, at a
        sixteenth of its cost (the one 256 x 256 product per term was 9 % of a control loop).
        The reflected walk is the free walk folded into +-bound (reflection at both walls is
        that fold of the free path). The draws and float operations are those of the plain
        numpy form (tests/firmware_model/test_imu_block.py keeps it): the work goes into
        preallocated buffers and the rows straight into the array the compiled loop reads.
        ``compiled`` (the compiled control loop's calls): the element-wise end in
        :mod:`.imu_kernel` (same bits) when every axis is bounded and numba compiles it."""
        n, taus, k = _BLOCK, np.array(FLICKER_TAUS), _BLOCK // _CHUNK
        if self._filter_dt != dt:
            phi = np.exp(-dt / taus)
            self._lower = _ar1_matrix(phi, _CHUNK)[:, None]  # (terms, 1, chunk, chunk)
            self._decay = (phi[:, None] ** np.arange(1, _CHUNK + 1)[None, :])[:, None, :, None]
            phi_chunk = phi**_CHUNK
            self._lower_k = _ar1_matrix(phi_chunk, k)
            self._decay_k = phi_chunk[:, None] ** np.arange(1, k + 1)[None, :]
            self._drive = np.sqrt(-np.expm1(-2.0 * dt / taus))[:, None] * self._flicker
            self._walk_dt = self._walk * math.sqrt(dt)
            self._decay_flat = np.ascontiguousarray(self._decay.reshape(len(taus), _CHUNK))
            self._filter_dt = dt
        z, local, tmp = self._z, self._local, self._tmp
        self.rng.standard_normal(out=z)  # the draws of standard_normal((terms, n, 6))
        np.multiply(z, self._drive[:, None, :], out=z)
        np.matmul(self._lower, z.reshape(len(taus), k, _CHUNK, 6), out=local)
        ends = np.matmul(self._lower_k, local[:, :, -1, :]) + (
            self._decay_k[:, :, None] * self._gm[:, None, :])  # state at each chunk's end
        before = np.concatenate([self._gm[:, None, :], ends[:, :-1, :]], axis=1)
        self._gm = ends[:, -1, :]
        fold_b = self._fold_b
        fin = _compiled_finish() if compiled and fold_b is not None else None
        if fin is not None and fold_b is not None:
            free, white, rows, rw = self._free, self._white_z, np.empty((n, 12)), self._rw.copy()
            self.rng.standard_normal(out=free)
            self.rng.standard_normal(out=white)
            b, b4, b2 = fold_b
            fin(local, self._decay_flat, before, free, self._walk_dt, rw, b, b4, b2, white,
                self._white, rows)
            self._rw = rw
            self._arr, self._left, self._list = rows, n, None
            return
        np.multiply(self._decay, before[:, :, None, :], out=tmp)
        np.add(local, tmp, out=local)
        free = self._free
        self.rng.standard_normal(out=free)
        np.cumsum(free, axis=0, out=free)
        np.multiply(free, self._walk_dt, out=free)
        np.add(self._rw, free, out=free)
        self._rw = free[-1].copy()
        rows = np.empty((n, 12))
        rev = rows[::-1]
        if self._fold_b is not None:  # _fold(free, bound), every bound > 0
            b, b4, b2 = self._fold_b
            np.add(free, b, out=free)
            np.mod(free, b4, out=free)
            np.subtract(np.where(free < b2, free, b4 - free), b, out=free)
        else:
            free = _fold(free, self._bound)
        np.add(local.reshape(len(taus), n, 6).sum(axis=0), free, out=rev[:, :6])
        white = self._white_z
        self.rng.standard_normal(out=white)
        np.multiply(white, self._white, out=rev[:, 6:])
        self._arr, self._left, self._list = rows, n, None

    def next_row(self, dt: float) -> list[float]:
        """The next sample's 6 biases and 6 white noises (a new block when this one is used)."""
        if not self._left:
            self._block(dt)
        self._left -= 1
        rows = self._list
        if rows is None:
            rows = self._list = self._arr.tolist()
        return rows[self._left]

    def at_rest(self, n: int, dt: float) -> np.ndarray:
        """``n`` samples of a base at rest, shape (n, 6): gyro xyz, accel xyz; the same values
        ``n`` calls of :meth:`sample` give (without faults; for long analyses in bulk)."""
        p = self.params
        gain = np.array([1.0 + p.gyro_scale_error] * 3 + [1.0 + p.accel_scale_error] * 3)
        true = np.array([0.0, 0.0, 0.0, 0.0, 0.0, p.gravity]) * gain
        if not p.noise:
            return np.tile(true, (n, 1))
        parts: list[np.ndarray] = []
        got = 0
        while got < n:
            if not self._left:
                self._block(dt)
            take = min(n - got, self._left)
            parts.append(self._arr[self._left - take:self._left][::-1])
            self._left -= take
            got += take
        z = np.concatenate(parts) if parts else np.zeros((0, 12))
        turn_on = np.array(self.gyro_turn_on + self.accel_turn_on)
        return true + turn_on + z[:, :6] + z[:, 6:]

    def sample(self, omega_body: Vec3, accel_body: Vec3, dt: float) -> tuple[Vec3, Vec3]:
        """One sample: true angular velocity [rad/s] and base acceleration [m/s^2] (without
        gravity) in the base frame, ``dt`` [s] since the last sample -> (gyro, accel).

        Written out per axis (it runs at 100 Hz in every control loop); the arithmetic is
        ``out = (scale * true + bias) + white``, then the fault step, then saturation."""
        p = self.params
        o0, o1, o2 = float(omega_body[0]), float(omega_body[1]), float(omega_body[2])
        f0, f1 = float(accel_body[0]), float(accel_body[1])
        f2 = float(accel_body[2]) + p.gravity
        if p.noise:
            z = self.next_row(dt if dt > 0.0 else 1.0 / p.rate_hz)
            gs, as_ = 1.0 + p.gyro_scale_error, 1.0 + p.accel_scale_error
            gt, at, gb, ab = self.gyro_turn_on, self.accel_turn_on, self.gyro_bias, self.accel_bias
            gb[0], gb[1], gb[2] = gt[0] + z[0], gt[1] + z[1], gt[2] + z[2]
            ab[0], ab[1], ab[2] = at[0] + z[3], at[1] + z[4], at[2] + z[5]
            o0, o1, o2 = gs * o0 + gb[0] + z[6], gs * o1 + gb[1] + z[7], gs * o2 + gb[2] + z[8]
            f0, f1, f2 = as_ * f0 + ab[0] + z[9], as_ * f1 + ab[1] + z[10], as_ * f2 + ab[2] + z[11]
        g_max, a_max = self._limits
        gf, af = self.gyro_fault, self.accel_fault
        gyro = (min(max(o0 + gf[0], -g_max), g_max), min(max(o1 + gf[1], -g_max), g_max),
                min(max(o2 + gf[2], -g_max), g_max))
        accel = (min(max(f0 + af[0], -a_max), a_max), min(max(f1 + af[1], -a_max), a_max),
                 min(max(f2 + af[2], -a_max), a_max))
        if not self.frozen:
            self._last = (gyro, accel)
        return self._last
