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


class ImuModel:
    """Stateful IMU: call :meth:`sample` once per output sample (nominally at ``rate_hz``)."""

    def __init__(self, params: ImuParams, rng: np.random.Generator | None = None) -> None:
        self.params = params
        self.rng = rng if rng is not None else np.random.default_rng(params.seed)
        zero = np.zeros(3)
        if params.noise:
            self.gyro_turn_on = self.rng.normal(0.0, params.gyro_turn_on_bias * DEG, 3)
            self.accel_turn_on = self.rng.normal(0.0, params.accel_turn_on_bias * 1e3 * MICRO_G, 3)
        else:
            self.gyro_turn_on, self.accel_turn_on = zero.copy(), zero.copy()
        self.gyro_bias = self.gyro_turn_on.copy()  # [rad/s] turn-on + walk
        self.accel_bias = self.accel_turn_on.copy()  # [m/s^2] turn-on + walk
        self.gyro_fault = zero.copy()  # [rad/s] injected bias steps
        self.accel_fault = zero.copy()  # [m/s^2] injected bias steps
        self.frozen = False
        self._last: tuple[Vec3, Vec3] = ((0.0, 0.0, 0.0), (0.0, 0.0, params.gravity))

    def bias_step(self, gyro: Vec3 = (0.0, 0.0, 0.0), accel: Vec3 = (0.0, 0.0, 0.0)) -> None:
        """Fault: add a bias step [rad/s] to the gyro and [m/s^2] to the accelerometer."""
        self.gyro_fault += np.asarray(gyro, dtype=float)
        self.accel_fault += np.asarray(accel, dtype=float)

    def freeze(self, on: bool = True) -> None:
        """Fault: while frozen, every sample repeats the last one (the model keeps running)."""
        self.frozen = on

    def sample(self, omega_body: Vec3, accel_body: Vec3, dt: float) -> tuple[Vec3, Vec3]:
        """One sample: true angular velocity [rad/s] and base acceleration [m/s^2] (without
        gravity) in the base frame, ``dt`` [s] since the last sample -> (gyro, accel)."""
        p = self.params
        omega = np.asarray(omega_body, dtype=float)
        force = np.asarray(accel_body, dtype=float) + np.array([0.0, 0.0, p.gravity])
        if p.noise:
            z = self.rng.standard_normal(12)
            root_dt = math.sqrt(max(dt, 0.0))
            g_bound = p.bias_walk_bound * p.gyro_bias_instability * DEG_PER_HOUR
            a_bound = p.bias_walk_bound * p.accel_bias_instability * MICRO_G
            walk_g = self.gyro_bias + p.gyro_random_walk * root_dt * z[6:9]
            walk_a = self.accel_bias + p.accel_random_walk * root_dt * z[9:12]
            self.gyro_bias = reflect(walk_g, self.gyro_turn_on, g_bound)
            self.accel_bias = reflect(walk_a, self.accel_turn_on, a_bound)
            omega = (1.0 + p.gyro_scale_error) * omega + self.gyro_bias + gyro_sigma(p) * z[0:3]
            force = (1.0 + p.accel_scale_error) * force + self.accel_bias + accel_sigma(p) * z[3:6]
        g_max, a_max = p.gyro_full_scale * DEG, p.accel_full_scale * STANDARD_GRAVITY
        gyro = np.clip(omega + self.gyro_fault, -g_max, g_max)
        accel = np.clip(force + self.accel_fault, -a_max, a_max)
        if not self.frozen:
            self._last = (_vec3(gyro), _vec3(accel))
        return self._last


def _vec3(a: np.ndarray) -> Vec3:
    return float(a[0]), float(a[1]), float(a[2])
