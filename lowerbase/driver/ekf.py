"""Planar EKF fusing wheel odometry with the z-gyro: heading from the gyro, speed from the wheels.

ROS-free and clock-free (time is passed in). Built on filterpy's
:class:`~filterpy.kalman.ExtendedKalmanFilter`: the filter is reachable as :attr:`PlanarEkf.kf`
and its ``x``, ``P``, ``x_prior``, ``P_prior``, ``y``, ``S``, ``K`` stay inspectable.

State ``[x, y, yaw, v, w, b]``: position [m], heading [rad] (continuous, not wrapped), forward
velocity [m/s], yaw rate [rad/s] and the z-gyro's bias [rad/s].

* Predict: constant velocity and turn rate over the step (second-order midpoint position);
  process noise from white linear and angular acceleration, a little lateral slip, and a random
  walk of the gyro bias.
* Wheel update: measures ``(v, w)`` with the odometry's twist covariance. While moving it
  corrects only the velocities, not the pose or the gyro bias (a Schmidt "consider" update:
  those states' uncertainty still weighs the measurement, their values stay). The wheel errors
  are systematic (E_d, E_b: a steady yaw-rate offset at a steady speed), not white; treated as
  white, every sample would shift the heading through its correlation with the yaw rate and the
  bias through the gyro, and within a minute the wheels would own the heading again. The bias
  is learned at standstill, where the wheels' zero is exact. A Mahalanobis gate rejects
  outliers: a wheel that slips or spins free makes the wheel yaw rate disagree with the gyro,
  then ``w`` is rejected and ``v`` down-weighted (a slipping wheel corrupts it by half the
  slip); only if both disagree is the whole measurement dropped.
* Gyro update: measures ``w + b``, gated as well; the bias is updated only at standstill
  (while moving it is a consider state, so wheel errors cannot leak into it). The driver
  queues the gyro samples (:meth:`PlanarEkf.add_gyro`, 100 Hz) and fuses their mean, with
  variance sigma^2/n, right before each wheel update (50 Hz): one predict and two small
  updates per wheel cycle instead of three of each. The summed rate, hence the integrated
  heading, is the same; the yaw rate used between updates is one gyro sample later.
* Standstill: when the wheels have reported exactly no motion for ``standstill_time``, a
  zero-velocity pseudo-measurement pins ``v`` and ``w`` to zero, so the gyro then measures pure
  bias and the bias converges (physical-data.md 5.2: a standstill bias estimate is mandatory).
  The pose covariance does not grow then (no process noise on a base that does not move).

A gate that keeps rejecting one sensor would lock the filter onto a wrong state; after
``max_consecutive_rejections`` rejections in a row the next measurement is accepted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Any, NamedTuple

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

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


_H_TWIST = _selector(V, W)
_H_V = _selector(V)
_H_W = _selector(W)
_H_GYRO = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 1.0]])
#: states a moving wheel measurement may not correct (see the module docstring)
_WHEEL_CONSIDER = (X, Y, YAW, B)
#: gain masks: 0 for the consider states, 1 for the others (a column, broadcast over K)
_KEEP: dict[tuple[int, ...], np.ndarray] = {
    c: np.array([[0.0 if i in c else 1.0] for i in range(DIM_X)])
    for c in (_WHEEL_CONSIDER, (B,))}
#: covariance masks: 0 on the consider x consider block (kept by the update), 1 elsewhere
_KEEP_BLOCK: dict[tuple[int, ...], np.ndarray] = {
    c: 1.0 - (1.0 - m) @ (1.0 - m).T for c, m in _KEEP.items()}


class _Innovation(NamedTuple):
    y: np.ndarray  #: innovation z - H x
    s: np.ndarray  #: its covariance H P H^T + R
    si: np.ndarray  #: S^-1
    pht: np.ndarray  #: P H^T
    d2: float  #: Mahalanobis distance squared y^T S^-1 y


class PlanarEkf:
    """EKF over ``[x, y, yaw, v, w, gyro_bias]``; see the module docstring."""

    def __init__(self, noise: EkfNoise | None = None, stamp: float | None = None) -> None:
        self.noise = noise if noise is not None else EkfNoise()
        self.kf: Any = ExtendedKalmanFilter(dim_x=DIM_X, dim_z=2)
        #: time [s] the state refers to (None until the first stamped call)
        self.stamp: float | None = stamp
        self.reset()

    # -- set-up ------------------------------------------------------------------------------

    def reset(
        self,
        x: float = 0.0,
        y: float = 0.0,
        yaw: float = 0.0,
        *,
        gyro_bias: float = 0.0,
        pose_sigma: tuple[float, float, float] = (1e-3, 1e-3, 1e-3),
    ) -> None:
        """Set the pose [m, m, rad] with 1-sigma ``pose_sigma``, zero velocity, a bias guess."""
        n = self.noise
        self.kf.x = np.array([[x], [y], [yaw], [0.0], [0.0], [gyro_bias]], dtype=float)
        self.kf.P = np.diag(
            [
                pose_sigma[0] ** 2,
                pose_sigma[1] ** 2,
                pose_sigma[2] ** 2,
                n.initial_linear**2,
                n.initial_angular**2,
                n.initial_bias**2,
            ]
        )
        self.kf.x_prior = self.kf.x.copy()
        self.kf.P_prior = self.kf.P.copy()
        self._time = 0.0  # [s] advanced by predict; standstill timing works without stamps
        self._still_since: float | None = None
        self.innovation = np.zeros((0, 1))
        self.innovation_covariance = np.zeros((0, 0))
        #: Mahalanobis distance squared of the last gated measurement
        self.mahalanobis_sq = 0.0
        self.last_gate: Gate | None = None
        self._consecutive = {"wheel_linear": 0, "wheel_angular": 0, "gyro": 0}
        #: counts of gate outcomes, by sensor and outcome
        self.statistics: dict[str, int] = {}
        self._r_default = np.diag([n.wheel_linear**2, n.wheel_angular**2])
        # gyro samples queued by add_gyro: count, sum [rad/s], first and last stamp [s], sigma
        self._gyro_n, self._gyro_sum = 0, 0.0
        self._gyro_first = self._gyro_last = 0.0
        self._gyro_sigma = n.gyro_noise

    # -- inspection --------------------------------------------------------------------------

    @property
    def x(self) -> np.ndarray:
        """State ``[x, y, yaw, v, w, b]`` as a flat array (a copy)."""
        out: np.ndarray = np.array(self.kf.x, dtype=float).ravel()
        return out

    @property
    def P(self) -> np.ndarray:
        """State covariance (a copy)."""
        out: np.ndarray = np.array(self.kf.P, dtype=float)
        return out

    @property
    def x_prior(self) -> np.ndarray:
        """State after the last predict, before any update (flat copy)."""
        out: np.ndarray = np.array(self.kf.x_prior, dtype=float).ravel()
        return out

    @property
    def pose(self) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad] in (-pi, pi])."""
        s = self.kf.x
        return float(s[X, 0]), float(s[Y, 0]), math.remainder(float(s[YAW, 0]), math.tau)

    @property
    def yaw_unwrapped(self) -> float:
        """Heading [rad], continuous."""
        return float(self.kf.x[YAW, 0])

    @property
    def twist(self) -> tuple[float, float]:
        """(v [m/s], w [rad/s])."""
        return float(self.kf.x[V, 0]), float(self.kf.x[W, 0])

    @property
    def gyro_bias(self) -> float:
        """Estimated z-gyro bias [rad/s]."""
        return float(self.kf.x[B, 0])

    @property
    def is_standstill(self) -> bool:
        """True while the wheels have reported no motion for ``standstill_time``."""
        return (
            self._still_since is not None
            and self._time - self._still_since >= self.noise.standstill_time
        )

    def pose_covariance(self) -> np.ndarray:
        """Covariance of (x, y, yaw) [m^2, m*rad, rad^2]."""
        return self.P[X : YAW + 1, X : YAW + 1]

    def twist_covariance(self) -> np.ndarray:
        """Covariance of (v, w) [(m/s)^2, m*rad/s^2, (rad/s)^2]."""
        return self.P[V : W + 1, V : W + 1]

    # -- predict -----------------------------------------------------------------------------

    def predict(self, dt: float) -> None:
        """Propagate the state by ``dt`` [s] (split into steps of at most ``max_step``)."""
        if not math.isfinite(dt) or dt < 0:
            raise ValueError(f"dt must be finite and >= 0, got {dt}")
        if dt == 0:
            return
        steps = max(1, math.ceil(dt / self.noise.max_step))
        h = dt / steps
        kf = self.kf
        # a base known to stand still does not drift: its pose rows of P stay as they are
        # (as robot_localization and diff_drive_controller add no process noise then), while
        # v, w and the bias keep theirs, so the filter can follow when the base moves off
        frozen = kf.P[X : YAW + 1, :].copy() if self.is_standstill else None
        for _ in range(steps):
            # filterpy's predict() is linear (F x); the nonlinear step is done here, as its
            # documentation suggests, keeping F, Q, x_prior and P_prior in its attributes
            kf.F = motion_jacobian(kf.x, h)
            kf.Q = process_noise(kf.x, h, self.noise)
            kf.x = motion_model(kf.x, h)
            kf.P = kf.F @ kf.P @ kf.F.T + kf.Q
        if frozen is not None:
            kf.P[X : YAW + 1, :] = frozen
            kf.P[:, X : YAW + 1] = frozen.T
        kf.P = 0.5 * (kf.P + kf.P.T)
        kf.x_prior = kf.x.copy()
        kf.P_prior = kf.P.copy()
        self._time += dt
        if self.stamp is not None:
            self.stamp += dt

    def predict_to(self, stamp: float) -> None:
        """Propagate to time ``stamp`` [s]; a stamp in the past does nothing (late sample)."""
        if not math.isfinite(stamp):
            raise ValueError(f"stamp must be finite, got {stamp}")
        if self.stamp is None:
            self.stamp = float(stamp)
            return
        if stamp > self.stamp:
            self.predict(stamp - self.stamp)
            self.stamp = float(stamp)  # no accumulated rounding

    def hold(self, unknown_distance: float = 0.0, unknown_turn: float = 0.0) -> None:
        """The measurements stopped (link lost, or samples after a gap): hold the pose.

        Nothing is predicted through the gap: v and w become 0 with their initial uncertainty
        (the base's motion is unknown, not the last one), queued gyro samples are dropped and
        the next stamped measurement restarts the timeline without a predict. The pose may
        have moved by up to ``unknown_distance`` [m] and ``unknown_turn`` [rad] meanwhile (a
        base that was driving when the link went): their squares add to the pose variances.
        """
        if not (math.isfinite(unknown_distance) and math.isfinite(unknown_turn)):
            raise ValueError("unknown motion must be finite")
        kf, n = self.kf, self.noise
        self.discard_gyro()
        kf.x[V, 0] = kf.x[W, 0] = 0.0
        p = kf.P
        p[V : W + 1, :] = 0.0
        p[:, V : W + 1] = 0.0
        p[V, V], p[W, W] = n.initial_linear**2, n.initial_angular**2
        p[X, X] += unknown_distance**2
        p[Y, Y] += unknown_distance**2
        p[YAW, YAW] += unknown_turn**2
        kf.x_prior, kf.P_prior = kf.x.copy(), kf.P.copy()
        self._still_since = None
        self.stamp = None

    # -- updates -----------------------------------------------------------------------------

    def update_wheels(
        self,
        linear: float,
        angular: float,
        covariance: np.ndarray | tuple[float, ...] | None = None,
        stamp: float | None = None,
    ) -> Gate:
        """Wheel-odometry twist: ``linear`` [m/s], ``angular`` [rad/s].

        ``covariance`` is the 2x2 (or row-major 4-tuple) twist covariance of the odometry;
        default ``diag(wheel_linear^2, wheel_angular^2)``. Detects standstill and then applies
        the zero-velocity update instead. Gyro samples queued by :meth:`add_gyro` are applied
        first, as one measurement at this time.
        """
        if not (math.isfinite(linear) and math.isfinite(angular)):
            return self._count("wheel", Gate.INVALID)
        if stamp is not None:
            self.predict_to(stamp)
        if self._gyro_n:
            self._flush_gyro()
        n = self.noise
        if (
            abs(linear) <= n.standstill_threshold_linear
            and abs(angular) <= n.standstill_threshold_angular
        ):
            if self._still_since is None:
                self._still_since = self._time
        else:
            self._still_since = None
        if self.is_standstill:
            r = np.diag([n.standstill_linear**2, n.standstill_angular**2])
            z = np.zeros((2, 1))
            self._apply(z, _H_TWIST, r, self._innovation(z, _H_TWIST, r))
            return self._count("wheel", Gate.STANDSTILL)

        r = self._twist_r(covariance)
        z = np.array([[linear], [angular]])
        inn = self._innovation(z, _H_TWIST, r)
        y, s, d2 = inn.y, inn.s, inn.d2
        if d2 <= n.gate_2dof:
            self._consecutive["wheel_linear"] = self._consecutive["wheel_angular"] = 0
            self._apply(z, _H_TWIST, r, inn, consider=_WHEEL_CONSIDER)
            return self._count("wheel", Gate.ACCEPTED)
        v_pass = y.item(0, 0) ** 2 / s.item(0, 0) <= n.gate_1dof
        w_pass = y.item(1, 0) ** 2 / s.item(1, 1) <= n.gate_1dof
        v_ok = v_pass or self._force("wheel_linear")
        w_ok = w_pass or self._force("wheel_angular")
        if v_pass:
            self._consecutive["wheel_linear"] = 0
        if w_pass:
            self._consecutive["wheel_angular"] = 0
        if v_ok and w_ok:  # each plausible alone (jointly marginal), or forced back in
            self._apply(z, _H_TWIST, r, inn, consider=_WHEEL_CONSIDER)
            return self._count("wheel", Gate.ACCEPTED if v_pass and w_pass else Gate.FORCED)
        if v_ok:  # slipping wheel: yaw rate out, speed down-weighted
            z1, r1 = z[:1], r[:1, :1] * n.slip_inflation
            self._apply(z1, _H_V, r1, self._innovation(z1, _H_V, r1, keep=False),
                        consider=_WHEEL_CONSIDER)
            return self._count("wheel", Gate.ANGULAR_REJECTED)
        if w_ok:
            z1, r1 = z[1:], r[1:, 1:]
            self._apply(z1, _H_W, r1, self._innovation(z1, _H_W, r1, keep=False),
                        consider=_WHEEL_CONSIDER)
            return self._count("wheel", Gate.LINEAR_REJECTED)
        return self._count("wheel", Gate.REJECTED)

    def update_gyro(
        self, rate: float, stamp: float | None = None, sigma: float | None = None
    ) -> Gate:
        """z-gyro reading ``rate`` [rad/s] (measures ``w + b``), 1-sigma ``sigma`` [rad/s].

        Applied at once (queued samples of :meth:`add_gyro` first)."""
        if not math.isfinite(rate):
            return self._count("gyro", Gate.INVALID)
        if stamp is not None:
            self.predict_to(stamp)
        if self._gyro_n:
            self._flush_gyro()
        return self._gyro(rate, sigma if sigma is not None else self.noise.gyro_noise)

    def add_gyro(self, rate: float, stamp: float, sigma: float | None = None) -> Gate | None:
        """Queue a z-gyro sample [rad/s] taken at ``stamp`` [s] (1-sigma ``sigma``).

        The samples between two wheel updates are applied as one measurement, their mean with
        variance ``sigma^2 / n``, just before the next :meth:`update_wheels` (so the filter
        runs once per wheel cycle, not once per gyro sample). Samples spanning more than
        ``max_step`` (no wheels: an encoder fault) are applied without waiting. Returns
        ``Gate.INVALID`` for a non-finite sample (dropped), else the gate of a measurement
        applied now, or None when the sample was only queued.
        """
        if not (math.isfinite(rate) and math.isfinite(stamp)):
            return self._count("gyro", Gate.INVALID)
        sigma = self.noise.gyro_noise if sigma is None else sigma
        gate = None
        if self._gyro_n and (sigma != self._gyro_sigma
                             or stamp - self._gyro_first > self.noise.max_step):
            self.predict_to(self._gyro_last)
            gate = self._flush_gyro()
        if not self._gyro_n:
            self._gyro_first, self._gyro_sigma = stamp, sigma
        self._gyro_sum += rate
        self._gyro_n += 1
        self._gyro_last = stamp
        return gate

    @property
    def pending_gyro(self) -> int:
        """Gyro samples queued by :meth:`add_gyro`, not applied yet."""
        return self._gyro_n

    def discard_gyro(self) -> None:
        """Drop the queued gyro samples (the gyro was found faulty)."""
        self._gyro_n, self._gyro_sum = 0, 0.0

    # -- internals ---------------------------------------------------------------------------

    def _flush_gyro(self) -> Gate:
        n, mean = self._gyro_n, self._gyro_sum / self._gyro_n
        self.discard_gyro()
        return self._gyro(mean, self._gyro_sigma / math.sqrt(n))

    def _gyro(self, rate: float, sigma: float) -> Gate:
        r = np.array([[sigma**2]])
        z = np.array([[rate]])
        inn = self._innovation(z, _H_GYRO, r)
        gated = self.noise.gate_gyro and inn.d2 > self.noise.gate_1dof
        if gated and not self._force("gyro"):
            return self._count("gyro", Gate.REJECTED)
        forced = gated
        self._consecutive["gyro"] = 0
        # The bias is only observable at standstill, where the wheels' zero is exact. While
        # moving, a wheel/gyro disagreement is as likely a wheel radius or slip error as a
        # bias, and letting the bias absorb it turns a wheel error into a heading drift; so
        # the bias is a "consider" state then (its uncertainty counts, its value stays).
        self._apply(z, _H_GYRO, r, inn, consider=() if self.is_standstill else (B,))
        return self._count("gyro", Gate.FORCED if forced else Gate.ACCEPTED)

    def _twist_r(self, covariance: np.ndarray | tuple[float, ...] | None) -> np.ndarray:
        if covariance is None:
            return self._r_default
        r = np.asarray(covariance, dtype=float).reshape(2, 2)
        if not np.all(np.isfinite(r)) or r[0, 0] <= 0 or r[1, 1] <= 0:
            raise ValueError(f"wheel twist covariance must be finite and positive, got {r}")
        sym: np.ndarray = 0.5 * (r + r.T)
        return sym

    def _innovation(
        self, z: np.ndarray, h: np.ndarray, r: np.ndarray, keep: bool = True
    ) -> _Innovation:
        """Innovation ``y``, its covariance ``S`` and inverse, ``P H^T`` and Mahalanobis^2.

        ``keep``: also store y, S and the distance as the last gated measurement's."""
        kf = self.kf
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
        if keep:
            self.innovation, self.innovation_covariance, self.mahalanobis_sq = y, s, d2
        return _Innovation(y, s, si, pht, d2)

    def _apply(
        self, z: np.ndarray, h: np.ndarray, r: np.ndarray, inn: _Innovation,
        consider: tuple[int, ...] = (),
    ) -> None:
        """Kalman update with the gain's ``consider`` rows zeroed (Schmidt-Kalman).

        With no consider state this is filterpy's ``ExtendedKalmanFilter.update`` for a linear
        ``h`` (same attributes set). With consider states, those keep their value (zero gain)
        while their uncertainty still weighs the measurement. P follows the Joseph form
        ``(I - KH) P (I - KH)^T + K R K^T``, right for this sub-optimal gain too; for the gain
        ``K = M P H^T S^-1`` (``M`` zeroes the consider rows) it reduces exactly to
        ``P - C + N C N`` with ``C = P H^T S^-1 H P`` and ``N = I - M``: ``P - C``
        everywhere but the consider x consider block, which keeps its P. Spelled out so, the
        update is a handful of small products instead of LAPACK calls and 6x6 triple products.
        """
        kf = self.kf
        gain = inn.pht @ inn.si  # the optimal gain
        c = gain @ inn.pht.T
        if consider:
            gain = gain * _KEEP[consider]
            c *= _KEEP_BLOCK[consider]
        kf.S, kf.SI, kf.K, kf.y = inn.s, inn.si, gain, inn.y
        kf.x = kf.x + gain @ inn.y
        p = kf.P - c
        kf.P = 0.5 * (p + p.T)
        kf.z = z.copy()
        kf.x_post = kf.x.copy()
        kf.P_post = kf.P.copy()

    def _force(self, sensor: str) -> bool:
        self._consecutive[sensor] += 1
        if self._consecutive[sensor] > self.noise.max_consecutive_rejections:
            self._consecutive[sensor] = 0
            return True
        return False

    def _count(self, sensor: str, gate: Gate) -> Gate:
        key = f"{sensor}.{gate.value}"
        self.statistics[key] = self.statistics.get(key, 0) + 1
        self.last_gate = gate
        return gate
