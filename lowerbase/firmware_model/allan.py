"""The IMU's noise model in closed form: Allan variance of white noise, flicker (a sum of
Gauss-Markov terms) and random walk, and the flicker sigma that puts the Allan minimum at a
datasheet's bias instability (IEEE 952). Below the profile, which validates with it."""

from __future__ import annotations

import functools
import math
from typing import Protocol

import numpy as np

from lowerbase.errors import ConfigError

DEG = math.pi / 180.0  # [rad/deg]
DEG_PER_HOUR = DEG / 3600.0  # [rad/s per deg/h]
STANDARD_GRAVITY = 9.80665  # [m/s^2], 1 g
MICRO_G = 1e-6 * STANDARD_GRAVITY  # [m/s^2 per ug] (datasheet g is the standard one)
ALLAN_FLOOR = 0.664  #: Allan deviation minimum of flicker noise / bias instability (IEEE 952)
FLICKER_TAUS = tuple(10.0 ** (k / 2.0) for k in range(-1, 10))  #: [s] 0.3 .. 31623
_TAU_GRID = np.logspace(-3.0, 6.0, 1000)  # [s] where the model's Allan minimum is searched


class ImuNoise(Protocol):
    """The datasheet figures :func:`check_instabilities` reads (``[imu]`` of a profile)."""

    @property
    def gyro_noise_density(self) -> float: ...  # [deg/s/sqrt(Hz)]

    @property
    def gyro_bias_instability(self) -> float: ...  # [deg/h]

    @property
    def gyro_random_walk(self) -> float: ...  # [rad/s^2/sqrt(Hz)]

    @property
    def accel_noise_density(self) -> float: ...  # [ug/sqrt(Hz)]

    @property
    def accel_bias_instability(self) -> float: ...  # [ug]

    @property
    def accel_random_walk(self) -> float: ...  # [m/s^3/sqrt(Hz)]


def gauss_markov_avar(tau: np.ndarray, corr_time: float) -> np.ndarray:
    """Allan variance of a unit-variance first-order Gauss-Markov process (correlation time
    ``corr_time`` [s]) at averaging times ``tau`` [s]."""
    x = tau / corr_time
    with np.errstate(over="ignore", invalid="ignore"):
        exact = (2.0 / x) * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))
    series = 2.0 * (x / 3.0 - x * x / 4.0)  # small x: the exact form cancels
    return np.where(x < 1e-3, series, exact)


def model_avar(tau: np.ndarray, density: float, flicker: float, walk: float) -> np.ndarray:
    """Allan variance of white (``density``) + flicker (``flicker`` = sigma of each
    Gauss-Markov term) + random walk (``walk``); SI units."""
    gm = sum(gauss_markov_avar(tau, t) for t in FLICKER_TAUS)
    return density**2 / tau + flicker**2 * gm + walk**2 * tau / 3.0


@functools.lru_cache(maxsize=64)
def flicker_sigma(density: float, instability: float, walk: float, what: str = "imu") -> float:
    """Sigma of each Gauss-Markov term such that the Allan deviation's minimum is
    ``ALLAN_FLOOR * instability`` (SI units; 0 gives no flicker). ConfigError when white
    noise and random walk alone already lie above that floor. Kept per arguments (the
    bisection is ~30 ms, and every boot of every chassis makes an ImuModel)."""
    if instability <= 0.0:
        return 0.0
    target = (ALLAN_FLOOR * instability) ** 2
    floor = float(model_avar(_TAU_GRID, density, 0.0, walk).min())
    if floor >= target:
        raise ConfigError(
            f"{what} is below the Allan minimum that the noise density and random walk alone "
            f"give ({math.sqrt(floor) / ALLAN_FLOOR:.3g} in SI units); raise it, lower those, "
            "or set it to 0 for no flicker")
    lo, hi = 0.0, 10.0 * ALLAN_FLOOR * instability
    for _ in range(60):  # bisection: the minimum grows with the flicker sigma
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if model_avar(_TAU_GRID, density, mid, walk).min() < target else (
            lo, mid)
    return 0.5 * (lo + hi)


def check_instabilities(p: ImuNoise) -> None:
    """ConfigError (one line, naming the key) when a bias instability cannot be the Allan
    minimum because white noise and random walk alone lie above it."""
    flicker_sigma(p.gyro_noise_density * DEG, p.gyro_bias_instability * DEG_PER_HOUR,
                  p.gyro_random_walk, f"imu.gyro_bias_instability = {p.gyro_bias_instability:g}")
    flicker_sigma(p.accel_noise_density * MICRO_G, p.accel_bias_instability * MICRO_G,
                  p.accel_random_walk,
                  f"imu.accel_bias_instability = {p.accel_bias_instability:g}")
