"""6-axis MEMS IMU model (Kalibr noise model plus turn-on bias, scale error and saturation).

Per axis: ``out = (1 + scale) * true + bias + n``, where ``n`` is white noise with discrete
sigma ``density * sqrt(rate_hz)`` and ``bias`` = turn-on bias (drawn once) + a random walk
``b += random_walk * sqrt(dt) * N(0, 1)`` that reflects at +-``bias_walk_bound`` x the bias
instability around the turn-on value, so it stays bounded over hours. The accelerometer
measures specific force: the base acceleration plus ``gravity`` on +z (+9.81 m/s^2 at rest,
base assumed level). With ``noise = false`` the sensor is ideal and outputs are exact; the
fault hooks (:meth:`ImuModel.bias_step`, :meth:`ImuModel.freeze`) work either way.
"""

from __future__ import annotations

import math

import numpy as np

from lowerbase.firmware_model.profile import STANDARD_GRAVITY, ImuParams

Vec3 = tuple[float, float, float]

DEG = math.pi / 180.0  # [rad/deg]
DEG_PER_HOUR = DEG / 3600.0  # [rad/s per deg/h]
MICRO_G = 1e-6 * STANDARD_GRAVITY  # [m/s^2 per ug] (datasheet g is the standard one)


def gyro_sigma(params: ImuParams) -> float:
    """Discrete white-noise sigma of a gyro sample [rad/s]: density * sqrt(rate_hz)."""
    return params.gyro_noise_density * DEG * math.sqrt(params.rate_hz)


def accel_sigma(params: ImuParams) -> float:
    """Discrete white-noise sigma of an accel sample [m/s^2]: density * sqrt(rate_hz)."""
    return params.accel_noise_density * MICRO_G * math.sqrt(params.rate_hz)


def reflect(x: np.ndarray, center: np.ndarray, bound: float) -> np.ndarray:
    """Reflect ``x`` into [center - bound, center + bound] (elementwise; clipped after one fold)."""
    y = x - center
    y = np.where(y > bound, 2.0 * bound - y, y)
    y = np.where(y < -bound, -2.0 * bound - y, y)
    return center + np.clip(y, -bound, bound)


def _reflect1(x: float, center: float, bound: float) -> float:
    """Scalar :func:`reflect`."""
    y = x - center
    if y > bound:
        y = 2.0 * bound - y
    if y < -bound:
        y = -2.0 * bound - y
    return center + min(max(y, -bound), bound)


_BLOCK = 256  # samples of normals drawn from the generator at once


class ImuModel:
    """Stateful IMU: call :meth:`sample` once per output sample (nominally at ``rate_hz``).

    Plain floats per axis (a sample costs microseconds); the normals come from the numpy
    generator in blocks, so a seed gives the same sequence on every machine.
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
        self.gyro_bias = list(self.gyro_turn_on)  # [rad/s] turn-on + walk
        self.accel_bias = list(self.accel_turn_on)  # [m/s^2] turn-on + walk
        self.gyro_fault = [0.0, 0.0, 0.0]  # [rad/s] injected bias steps
        self.accel_fault = [0.0, 0.0, 0.0]  # [m/s^2] injected bias steps
        self.frozen = False
        self._last: tuple[Vec3, Vec3] = ((0.0, 0.0, 0.0), (0.0, 0.0, params.gravity))
        self._normals: list[float] = []
        self._g_sigma = gyro_sigma(params)
        self._a_sigma = accel_sigma(params)
        self._g_bound = params.bias_walk_bound * params.gyro_bias_instability * DEG_PER_HOUR
        self._a_bound = params.bias_walk_bound * params.accel_bias_instability * MICRO_G

    def bias_step(self, gyro: Vec3 = (0.0, 0.0, 0.0), accel: Vec3 = (0.0, 0.0, 0.0)) -> None:
        """Fault: add a bias step [rad/s] to the gyro and [m/s^2] to the accelerometer."""
        for i in range(3):
            self.gyro_fault[i] += float(gyro[i])
            self.accel_fault[i] += float(accel[i])

    def freeze(self, on: bool = True) -> None:
        """Fault: while frozen, every sample repeats the last one (the model keeps running)."""
        self.frozen = on

    def _draw(self) -> list[float]:
        if not self._normals:
            self._normals = self.rng.standard_normal(12 * _BLOCK).tolist()
            self._normals.reverse()
        normals = self._normals
        return [normals.pop() for _ in range(12)]

    def sample(self, omega_body: Vec3, accel_body: Vec3, dt: float) -> tuple[Vec3, Vec3]:
        """One sample: true angular velocity [rad/s] and base acceleration [m/s^2] (without
        gravity) in the base frame, ``dt`` [s] since the last sample -> (gyro, accel)."""
        p = self.params
        omega = [float(omega_body[0]), float(omega_body[1]), float(omega_body[2])]
        force = [float(accel_body[0]), float(accel_body[1]), float(accel_body[2]) + p.gravity]
        if p.noise:
            z = self._draw()
            root_dt = math.sqrt(max(dt, 0.0))
            gs, as_ = 1.0 + p.gyro_scale_error, 1.0 + p.accel_scale_error
            for i in range(3):
                self.gyro_bias[i] = _reflect1(
                    self.gyro_bias[i] + p.gyro_random_walk * root_dt * z[6 + i],
                    self.gyro_turn_on[i], self._g_bound)
                self.accel_bias[i] = _reflect1(
                    self.accel_bias[i] + p.accel_random_walk * root_dt * z[9 + i],
                    self.accel_turn_on[i], self._a_bound)
                omega[i] = gs * omega[i] + self.gyro_bias[i] + self._g_sigma * z[i]
                force[i] = as_ * force[i] + self.accel_bias[i] + self._a_sigma * z[3 + i]
        g_max, a_max = p.gyro_full_scale * DEG, p.accel_full_scale * STANDARD_GRAVITY
        gyro = tuple(min(max(omega[i] + self.gyro_fault[i], -g_max), g_max) for i in range(3))
        accel = tuple(min(max(force[i] + self.accel_fault[i], -a_max), a_max) for i in range(3))
        if not self.frozen:
            self._last = (gyro, accel)  # type: ignore[assignment]
        return self._last
