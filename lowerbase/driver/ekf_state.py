"""The state, time line and update arithmetic of the planar EKF (:mod:`lowerbase.driver.ekf`).

:class:`EkfState` holds the filter's arrays (:class:`~lowerbase.driver.ekf_filter.FilterState`:
filterpy's names), the stamp and the standstill timer, predicts and
holds, and steps the time line by intervals (:meth:`EkfState._begin` moves the rates to the next
stamp, the measurements update them, :meth:`EkfState._finish` drives the pose over the interval
with them). :class:`~lowerbase.driver.ekf.PlanarEkf` adds the wheel and gyro measurements.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from lowerbase.driver.ekf_filter import FilterState
from lowerbase.driver.ekf_kernels import CycleWorkspace, compile_kernels, drive, measure
from lowerbase.driver.ekf_model import (
    DIM_X,
    YAW,
    B,
    EkfNoise,
    Gate,
    Innovation,
    V,
    W,
    X,
    Y,
    apply_update,
    innovation,
    motion_jacobian,
    motion_model,
    process_noise,
)

#: per set of consider states: 1 for the states a measurement may correct, 0 for the others
_KEEP: dict[tuple[int, ...], np.ndarray] = {
    c: np.array([0 if i in c else 1 for i in range(DIM_X)], dtype=np.uint8)
    for c in ((), (X, Y, YAW, B), (B,))}


#: the statistics' keys, "sensor.outcome"
_KEYS = {(sensor, gate.value): f"{sensor}.{gate.value}" for sensor in ("wheel", "gyro")
         for gate in Gate}


class Span(NamedTuple):
    """An interval of the timeline: its start [s] (None: no interval), length [s], and
    whether the base stood still at its start."""

    start: float | None
    dt: float
    frozen: bool


_NO_SPAN = Span(None, 0.0, False)


class EkfState:
    """The state, time line and update arithmetic of :class:`~lowerbase.driver.ekf.PlanarEkf`
    (which adds the measurements): ``[x, y, yaw, v, w, gyro_bias]``, see that module."""

    def __init__(self, noise: EkfNoise | None = None, stamp: float | None = None) -> None:
        compile_kernels()
        self.noise = noise if noise is not None else EkfNoise()
        self.kf: Any = FilterState(DIM_X, 2)
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
        #: the compiled wheel cycle's outputs (kf.y, S, SI, K, z, x_post, P_post are views)
        self._workspace = CycleWorkspace()
        #: the rates' white-noise densities (v, w, bias), per second of interval
        self._rate_q = np.array([n.linear_accel**2, n.angular_accel**2, n.gyro_bias_walk**2])
        #: the covariance of the zero-velocity pseudo-measurement at standstill
        self._r_still = np.diag([n.standstill_linear**2, n.standstill_angular**2])
        # gyro samples queued by add_gyro: stamps [s], rates [rad/s], their sigma [rad/s]; and
        # the last sample fused (stamp, rate): the start of the next interval's trapezoid
        self._gyro_times: list[float] = []
        self._gyro_rates: list[float] = []
        self._gyro_sigma = n.gyro_noise
        self._gyro_prev: tuple[float, float] | None = None

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
        x, y, yaw = self.kf.x[X:YAW + 1, 0].tolist()  # X, Y, YAW: 0, 1, 2
        return x, y, math.remainder(yaw, math.tau)

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

    def covariances(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`pose_covariance` and :meth:`twist_covariance`, each its own copy, from one
        read of the state covariance (driver_base's /odom at 50 Hz)."""
        P = self.kf.P
        return (np.array(P[X : YAW + 1, X : YAW + 1], dtype=float),
                np.array(P[V : W + 1, V : W + 1], dtype=float))

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

    # -- the time line and the update arithmetic --------------------------------------------

    def discard_gyro(self) -> None:
        """Drop the queued gyro samples (the gyro was found faulty)."""
        self._gyro_times, self._gyro_rates = [], []
        self._gyro_prev = None

    def _begin(self, stamp: float | None, noise: bool = True) -> Span:
        """Start the interval to ``stamp``: the rates (v, w, b) get their process noise (unless
        not ``noise``: the caller's :func:`~lowerbase.driver.ekf_kernels.wheel_cycle` adds it,
        or :meth:`_rate_noise`) and the time moves on; the pose waits for :meth:`_finish`, once
        the measurements have updated the rates to the interval's means. A stamp in the past
        or the first stamp: no interval."""
        if stamp is None:
            return _NO_SPAN
        if not math.isfinite(stamp):
            raise ValueError(f"stamp must be finite, got {stamp}")
        if self.stamp is None or stamp <= self.stamp:
            if self.stamp is None:
                self.stamp = float(stamp)
            return _NO_SPAN
        span = Span(self.stamp, stamp - self.stamp, self.is_standstill)
        if noise:
            self._rate_noise(span)
        self._time += span.dt
        self.stamp = float(stamp)
        return span

    def _rate_noise(self, span: Span) -> None:
        """P + rate_noise(dt), in place (its only nonzero entries); x_prior and P_prior."""
        kf, n = self.kf, self.noise
        p = kf.P
        p[V, V] += n.linear_accel**2 * span.dt
        p[W, W] += n.angular_accel**2 * span.dt
        p[B, B] += n.gyro_bias_walk**2 * span.dt
        kf.x_prior, kf.P_prior = kf.x.copy(), p.copy()

    def _finish(self, span: Span) -> None:
        """Drive the pose over ``span`` with the rates as they are now (the interval's means),
        in steps of at most ``max_step``; at standstill the pose covariance stays."""
        if span.dt <= 0:
            return
        drive(self.kf.x, self.kf.P, span.dt, self.noise.max_step, span.frozen,
              self.noise.lateral_slip**2)

    def _innovation(
        self, z: np.ndarray, h: np.ndarray, r: np.ndarray, keep: bool = True
    ) -> Innovation:
        """:func:`~lowerbase.driver.ekf_model.innovation`; ``keep``: also store y, S and the
        distance as the last gated measurement's."""
        inn = innovation(self.kf, z, h, r)
        if keep:
            self.innovation, self.innovation_covariance, self.mahalanobis_sq = inn.y, inn.s, inn.d2
        return inn

    def _apply(
        self, z: np.ndarray, h: np.ndarray, r: np.ndarray, inn: Innovation,
        consider: tuple[int, ...] = (),
    ) -> None:
        """:func:`~lowerbase.driver.ekf_model.apply_update` (``h``, ``r`` are in ``inn``)."""
        apply_update(self.kf, z, inn, consider)

    def _measure(
        self, z: np.ndarray, h: np.ndarray, r: np.ndarray, consider: tuple[int, ...] = (),
        gate: float | None = None, keep: bool = True,
    ) -> tuple[float, bool, np.ndarray, np.ndarray]:
        """The innovation of ``z`` and, unless a ``gate`` is given and the Mahalanobis^2 is
        not within it, the update (with ``consider`` states), both by the compiled
        :func:`~lowerbase.driver.ekf_kernels.measure` on ``kf.x`` and ``kf.P`` in place;
        filterpy's attributes set as :func:`~lowerbase.driver.ekf_model.apply_update` sets
        them. ``keep``: store y, S and the distance as the last gated measurement's.
        Returns ``(d2, applied, y, S)``."""
        kf, m = self.kf, len(h)
        y, s, si, gain = np.empty((m, 1)), np.empty((m, m)), np.empty((m, m)), np.empty((DIM_X, m))
        d2, applied = measure(kf.x, kf.P, h, z, r, _KEEP[consider], gate is not None,
                              0.0 if gate is None else gate, y, s, si, gain)
        if keep:
            self.innovation, self.innovation_covariance, self.mahalanobis_sq = y, s, d2
        if applied:
            kf.S, kf.SI, kf.K, kf.y = s, si, gain, y
            kf.z = z  # made for this measurement (not a shared constant)
            kf.x_post = kf.x.copy()
            kf.P_post = kf.P.copy()
        return d2, applied, y, s

    def _force(self, sensor: str) -> bool:
        self._consecutive[sensor] += 1
        if self._consecutive[sensor] > self.noise.max_consecutive_rejections:
            self._consecutive[sensor] = 0
            return True
        return False

    def _count(self, sensor: str, gate: Gate) -> Gate:
        key = _KEYS[sensor, gate._value_]  # (Enum's own __hash__ runs Python code)
        self.statistics[key] = self.statistics.get(key, 0) + 1
        self.last_gate = gate
        return gate
