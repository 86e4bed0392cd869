"""The model pieces of :class:`lowerbase.driver.ekf.PlanarEkf`: state layout, noise settings,
gate outcomes, the motion model with its Jacobian and process noise, the measurement matrices
and the interval weights of the gyro samples. ROS-free, numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any, NamedTuple

import numpy as np

from lowerbase.errors import ConfigError

#: state indices
X, Y, YAW, V, W, B = range(6)
DIM_X = 6
_EYE = np.eye(DIM_X)

# Chi-square quantiles at 99.9 % for 1 and 2 degrees of freedom.
CHI2_999_1DOF = 10.828
CHI2_999_2DOF = 13.816


@dataclass(frozen=True)
class EkfNoise:
    """Noise model and tuning of :class:`PlanarEkf` (1-sigma values)."""

    #: white linear acceleration driving v [m/s^2/sqrt(Hz)]
    linear_accel: float = 0.5
    #: white angular acceleration driving w [rad/s^2/sqrt(Hz)]: the chassis turns up at a few
    #: rad/s^2, and a loose w lets the (biased) wheels pull it between gyro samples
    angular_accel: float = 0.2
    #: random walk of the position across the heading (unmodelled sideways slip) [m/sqrt(s)]
    lateral_slip: float = 2e-3
    #: random walk of the gyro bias (bias instability, warm-up drift) [rad/s/sqrt(s)]
    gyro_bias_walk: float = 1e-5
    #: z-gyro white noise per sample [rad/s]
    gyro_noise: float = 2e-3
    #: wheel linear velocity noise used when the caller gives no covariance [m/s]
    wheel_linear: float = 0.01
    #: wheel yaw rate noise used when the caller gives no covariance [rad/s]; covers the
    #: systematic errors (1 % radius error: 0.016 rad/s at 0.8 m/s on a 0.5 m track)
    wheel_angular: float = 0.08
    #: sigma of the zero-velocity pseudo-measurement at standstill [m/s]
    standstill_linear: float = 1e-4
    #: sigma of the zero-yaw-rate pseudo-measurement at standstill [rad/s]
    standstill_angular: float = 1e-5
    #: wheels must have reported no motion this long before standstill is declared [s]
    standstill_time: float = 0.2
    #: |v| [m/s] and |w| [rad/s] at or below which the wheels report no motion
    standstill_threshold_linear: float = 1e-9
    standstill_threshold_angular: float = 1e-9
    #: Mahalanobis^2 gate for a 2-D wheel measurement (chi^2, 2 dof)
    gate_2dof: float = CHI2_999_2DOF
    #: Mahalanobis^2 gate for a 1-D measurement (chi^2, 1 dof)
    gate_1dof: float = CHI2_999_1DOF
    #: gate the gyro too; off by default: the gyro is the yaw-rate reference (a slipping wheel
    #: makes the true rate jump, and only the gyro sees it), its own failure (frozen output)
    #: is flagged by the lower computer (StatusCode IMU_FAULT) and the driver stops fusing it
    gate_gyro: bool = False
    #: variance factor on the wheel v when the wheel w was rejected as slipping
    slip_inflation: float = 100.0
    #: rejections in a row after which a sensor is accepted again (avoids lock-out)
    max_consecutive_rejections: int = 100
    #: initial sigmas of v [m/s], w [rad/s], gyro bias [rad/s]
    initial_linear: float = 0.1
    initial_angular: float = 0.1
    initial_bias: float = 0.1
    #: predictions longer than this are split into sub-steps [s]
    max_step: float = 0.05

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(f"EKF noise {name} must be finite and >= 0, got {value!r}")
        for name in (
            "gyro_noise",
            "wheel_linear",
            "wheel_angular",
            "standstill_linear",
            "standstill_angular",
            "gate_1dof",
            "gate_2dof",
            "max_step",
        ):
            if getattr(self, name) <= 0:
                raise ConfigError(f"EKF noise {name} must be > 0")


class Gate(Enum):
    """What happened to a measurement."""

    ACCEPTED = "accepted"
    REJECTED = "rejected"
    #: wheel measurement: the yaw rate was rejected, the speed used with inflated noise
    ANGULAR_REJECTED = "angular_rejected"
    #: wheel measurement: the speed was rejected, the yaw rate used
    LINEAR_REJECTED = "linear_rejected"
    #: wheel measurement at standstill: zero-velocity update applied
    STANDSTILL = "standstill"
    #: accepted despite failing the gate, after too many rejections in a row
    FORCED = "forced"
    #: a non-finite value: ignored
    INVALID = "invalid"


def motion_model(x: np.ndarray, dt: float) -> np.ndarray:
    """State after ``dt`` [s] of constant v and w (midpoint position step)."""
    out = np.array(x, dtype=float, copy=True)
    v, w, yaw = out.item(V, 0), out.item(W, 0), out.item(YAW, 0)
    mid = yaw + 0.5 * w * dt
    out[X, 0] += v * dt * math.cos(mid)
    out[Y, 0] += v * dt * math.sin(mid)
    out[YAW, 0] = yaw + w * dt
    return out


def motion_jacobian(x: np.ndarray, dt: float) -> np.ndarray:
    """d motion_model / d x at ``x`` for a step of ``dt`` [s]."""
    v, w = x.item(V, 0), x.item(W, 0)
    mid = x.item(YAW, 0) + 0.5 * w * dt
    c, s = math.cos(mid), math.sin(mid)
    f = _EYE.copy()
    f[X, YAW] = -v * dt * s
    f[X, V] = dt * c
    f[X, W] = -v * dt * s * 0.5 * dt
    f[Y, YAW] = v * dt * c
    f[Y, V] = dt * s
    f[Y, W] = v * dt * c * 0.5 * dt
    f[YAW, W] = dt
    return f


def process_noise(x: np.ndarray, dt: float, noise: EkfNoise) -> np.ndarray:
    """Discrete process noise for a step of ``dt`` [s] (white-acceleration model)."""
    yaw = x.item(YAW, 0)
    c, s = math.cos(yaw), math.sin(yaw)
    qa, qw = noise.linear_accel**2, noise.angular_accel**2
    pos = qa * dt**3 / 3  # along the heading u = (c, s)
    lat = noise.lateral_slip**2 * dt  # across it, n = (-s, c)
    xv, yv = qa * dt**2 / 2 * c, qa * dt**2 / 2 * s
    xy = (pos - lat) * c * s
    yaw_w = qw * dt**2 / 2
    return np.array([
        [pos * c * c + lat * s * s, xy, 0.0, xv, 0.0, 0.0],
        [xy, pos * s * s + lat * c * c, 0.0, yv, 0.0, 0.0],
        [0.0, 0.0, qw * dt**3 / 3, 0.0, yaw_w, 0.0],
        [xv, yv, 0.0, qa * dt, 0.0, 0.0],
        [0.0, 0.0, yaw_w, 0.0, qw * dt, 0.0],
        [0.0, 0.0, 0.0, 0.0, 0.0, noise.gyro_bias_walk**2 * dt],
    ])


def _selector(*indices: int) -> np.ndarray:
    h = np.zeros((len(indices), DIM_X))
    for row, i in enumerate(indices):
        h[row, i] = 1.0
    return h


H_TWIST = _selector(V, W)
H_V = _selector(V)
H_W = _selector(W)
H_GYRO = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 1.0]])
#: states a moving wheel measurement may not correct (see the module docstring)
WHEEL_CONSIDER = (X, Y, YAW, B)
#: gain masks: 0 for the consider states, 1 for the others (a column, broadcast over K)
KEEP: dict[tuple[int, ...], np.ndarray] = {
    c: np.array([[0.0 if i in c else 1.0] for i in range(DIM_X)])
    for c in (WHEEL_CONSIDER, (B,))}
#: covariance masks: 0 on the consider x consider block (kept by the update), 1 elsewhere
KEEP_BLOCK: dict[tuple[int, ...], np.ndarray] = {
    c: 1.0 - (1.0 - m) @ (1.0 - m).T for c, m in KEEP.items()}


def rate_noise(dt: float, noise: EkfNoise) -> np.ndarray:
    """Process noise of the rates ``v``, ``w`` and the bias ``b`` over an interval of ``dt``
    [s], the pose's rows and columns zero: the change of the interval-mean rates from one
    interval to the next (white accelerations, the bias random walk)."""
    q = np.zeros((DIM_X, DIM_X))
    q[V, V] = noise.linear_accel**2 * dt
    q[W, W] = noise.angular_accel**2 * dt
    q[B, B] = noise.gyro_bias_walk**2 * dt
    return q


def slip_noise(x: np.ndarray, dt: float, noise: EkfNoise) -> np.ndarray:
    """Process noise of the pose over an interval of ``dt`` [s] driven at known mean rates:
    only the unmodelled sideways slip, across the heading."""
    yaw = x.item(YAW, 0)
    n = np.array([-math.sin(yaw), math.cos(yaw)])
    q = np.zeros((DIM_X, DIM_X))
    q[X : Y + 1, X : Y + 1] = noise.lateral_slip**2 * dt * np.outer(n, n)
    return q


def interval_weights(times: Sequence[float], t0: float, t1: float) -> np.ndarray:
    """Weights ``w_i`` (summing to 1) with ``sum(w_i r_i)`` the mean over ``[t0, t1]`` of the
    rate sampled as ``r_i`` at ``times`` (ascending): the trapezoid rule on the straight lines
    between the samples, the first and the last sample held before and after them.

    Exact for a rate that is linear in time between the samples and constant outside them;
    so a constant rate, and a ramp sampled at both ends of the interval, come out exact.
    """
    return np.array(interval_weight_list(times, t0, t1))


def interval_weight_list(times: Sequence[float], t0: float, t1: float) -> list[float]:
    """:func:`interval_weights` as a list of floats (the EKF's per-cycle path: a handful of
    samples, where numpy's per-call cost exceeds the arithmetic)."""
    n = len(times)
    if n == 0:
        raise ValueError("no samples")
    span = t1 - t0
    if not span > 0:  # no interval: the samples' plain mean
        return [1.0 / n] * n
    # (max/min written as conditionals, the same values: this runs every wheel cycle)
    weights = [0.0] * n
    first, last = times[0], times[-1]
    held = (first if first < t1 else t1) - t0
    weights[0] += held if held > 0.0 else 0.0  # before the first sample: held
    held = t1 - (last if last > t0 else t0)
    weights[-1] += held if held > 0.0 else 0.0  # after the last one: held
    for i in range(n - 1):
        a, b = times[i], times[i + 1]
        lo, hi = (a if a > t0 else t0), (b if b < t1 else t1)
        if hi <= lo or b <= a:
            continue
        # integral over [lo, hi] of the hat functions (b - t)/(b - a) and (t - a)/(b - a)
        weights[i] += (hi - lo) * (b - 0.5 * (lo + hi)) / (b - a)
        weights[i + 1] += (hi - lo) * (0.5 * (lo + hi) - a) / (b - a)
    return [w / span for w in weights]


def interval_mean3(times: Sequence[float], rates: Sequence[float], t0: float,
                   t1: float) -> tuple[float, float]:
    """``(sum w_i r_i, sum w_i^2)`` with :func:`interval_weight_list`'s weights, for three
    samples (the driver's cycle: the last sample before and two new ones), written out: the
    same operations in the same order, so the same bits (tests/driver/test_ekf_interval.py)."""
    a0, a1, a2 = times
    span = t1 - t0
    if not span > 0:
        w0 = w1 = w2 = 1.0 / 3
    else:
        w0 = w1 = w2 = 0.0
        held = (a0 if a0 < t1 else t1) - t0
        w0 += held if held > 0.0 else 0.0
        held = t1 - (a2 if a2 > t0 else t0)
        w2 += held if held > 0.0 else 0.0
        lo, hi = (a0 if a0 > t0 else t0), (a1 if a1 < t1 else t1)
        if not (hi <= lo or a1 <= a0):
            w0 += (hi - lo) * (a1 - 0.5 * (lo + hi)) / (a1 - a0)
            w1 += (hi - lo) * (0.5 * (lo + hi) - a0) / (a1 - a0)
        lo, hi = (a1 if a1 > t0 else t0), (a2 if a2 < t1 else t1)
        if not (hi <= lo or a2 <= a1):
            w1 += (hi - lo) * (a2 - 0.5 * (lo + hi)) / (a2 - a1)
            w2 += (hi - lo) * (0.5 * (lo + hi) - a1) / (a2 - a1)
        w0, w1, w2 = w0 / span, w1 / span, w2 / span
    r0, r1, r2 = rates
    mean = 0.0 + w0 * r0
    mean += w1 * r1
    mean += w2 * r2
    squares = 0.0 + w0 * w0
    squares += w1 * w1
    squares += w2 * w2
    return mean, squares


class Innovation(NamedTuple):
    """A measurement's innovation and the pieces of its update."""

    y: np.ndarray  #: innovation z - H x
    s: np.ndarray  #: its covariance H P H^T + R
    si: np.ndarray  #: S^-1
    pht: np.ndarray  #: P H^T
    d2: float  #: Mahalanobis distance squared y^T S^-1 y


def innovation(kf: Any, z: np.ndarray, h: np.ndarray, r: np.ndarray) -> Innovation:
    """Innovation ``y``, its covariance ``S`` and inverse, ``P H^T`` and Mahalanobis^2 of the
    measurement ``z = H x + noise(R)`` against the filter ``kf`` (its ``x``, ``P``)."""
    pht = kf.P @ h.T
    s = h @ pht + r
    y = z - h @ kf.x
    if len(s) == 1:
        si = 1.0 / s
        d2 = y.item(0, 0) ** 2 * si.item(0, 0)
    elif len(s) == 2:  # closed form: numpy's solve/inv cost more than the whole update
        a, b, c, d = s.item(0, 0), s.item(0, 1), s.item(1, 0), s.item(1, 1)
        det = a * d - b * c
        si = np.array([[d / det, -b / det], [-c / det, a / det]])
        y0, y1 = y.item(0, 0), y.item(1, 0)
        d2 = (y0 * (d * y0 - b * y1) + y1 * (a * y1 - c * y0)) / det
    else:  # pragma: no cover - every measurement here is 1-D or 2-D
        si = np.linalg.inv(s)
        d2 = float((y.T @ si @ y).item())
    return Innovation(y, s, si, pht, d2)


def apply_update(kf: Any, z: np.ndarray, inn: Innovation, consider: tuple[int, ...] = ()) -> None:
    """Kalman update of ``kf`` with the gain's ``consider`` rows zeroed (Schmidt-Kalman).

    With no consider state this is filterpy's ``ExtendedKalmanFilter.update`` for a linear
    ``h`` (same attributes set). With consider states, those keep their value (zero gain)
    while their uncertainty still weighs the measurement. P follows the Joseph form
    ``(I - KH) P (I - KH)^T + K R K^T``, right for this sub-optimal gain too; for the gain
    ``K = M P H^T S^-1`` (``M`` zeroes the consider rows) it reduces exactly to
    ``P - C + N C N`` with ``C = P H^T S^-1 H P`` and ``N = I - M``: ``P - C``
    everywhere but the consider x consider block, which keeps its P. Spelled out so, the
    update is a handful of small products instead of LAPACK calls and 6x6 triple products.
    """
    gain = inn.pht @ inn.si  # the optimal gain
    c = gain @ inn.pht.T
    if consider:
        gain = gain * KEEP[consider]
        c *= KEEP_BLOCK[consider]
    kf.S, kf.SI, kf.K, kf.y = inn.s, inn.si, gain, inn.y
    kf.x = kf.x + gain @ inn.y
    p = kf.P - c
    kf.P = 0.5 * (p + p.T)
    kf.z = z.copy()
    kf.x_post = kf.x.copy()
    kf.P_post = kf.P.copy()
