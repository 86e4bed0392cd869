"""Planar EKF fusing wheel odometry with the z-gyro: heading from the gyro, speed from the wheels.

ROS-free and clock-free (time is passed in); the model pieces and the update arithmetic are
in :mod:`lowerbase.driver.ekf_model`, run compiled by :mod:`lowerbase.driver.ekf_kernels`
(the usual wheel cycle is one call). The filter's arrays keep the names of filterpy's
``ExtendedKalmanFilter`` (:class:`~lowerbase.driver.ekf_filter.FilterState`, without importing
filterpy): the filter is reachable as :attr:`PlanarEkf.kf` and its ``x``, ``P``,
``x_prior``, ``P_prior``, ``y``, ``S``, ``K`` stay inspectable (after a compiled cycle the
last five are views the next cycle overwrites: copy them to keep them).

State ``[x, y, yaw, v, w, b]``: position [m], heading [rad] (continuous, not wrapped), forward
velocity [m/s], yaw rate [rad/s] and the z-gyro's bias [rad/s].

* Intervals: a wheel measurement (encoder counts over a cycle) and the gyro samples between two
  wheel cycles measure the mean rates over the interval since the last one. So the rates are
  updated first, then the pose is driven over the interval with them (constant rates, midpoint
  position): the heading follows a change of the turn rate at once, where predicting with the
  interval before's rate lagged it by a cycle (0.5 deg at 0.5 rad/s on 20 ms wheel cycles, for
  as long as the turn lasts). Process noise: white linear and angular acceleration on the rates,
  a little lateral slip on the pose, a random walk of the gyro bias. :meth:`PlanarEkf.predict`
  extrapolates with the current rates (white-acceleration model).
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
  queues the gyro samples (:meth:`PlanarEkf.add_gyro`, 100 Hz) and fuses their trapezoid mean
  over the interval, right before each wheel update (50 Hz): one step and two small updates per
  wheel cycle instead of three of each.
* Standstill: when the wheels have reported exactly no motion for ``standstill_time``, a
  zero-velocity pseudo-measurement pins ``v`` and ``w`` to zero, so the gyro then measures pure
  bias and the bias converges (physical-data.md 5.2: a standstill bias estimate is mandatory).
  The pose covariance does not grow then (no process noise on a base that does not move).

A gate that keeps rejecting one sensor would lock the filter onto a wrong state; after
``max_consecutive_rejections`` rejections in a row the next measurement is accepted.
"""

from __future__ import annotations

import math

import numpy as np

from lowerbase.driver.ekf_kernels import wheel_cycle
from lowerbase.driver.ekf_model import (
    CHI2_999_1DOF,
    CHI2_999_2DOF,
    DIM_X,
    H_GYRO,
    H_TWIST,
    H_V,
    H_W,
    WHEEL_CONSIDER,
    YAW,
    B,
    EkfNoise,
    Gate,
    V,
    W,
    X,
    Y,
    interval_mean3,
    interval_weight_list,
    interval_weights,
    motion_jacobian,
    motion_model,
    process_noise,
)
from lowerbase.driver.ekf_state import EkfState, Span

__all__ = [
    "CHI2_999_1DOF",
    "CHI2_999_2DOF",
    "DIM_X",
    "YAW",
    "B",
    "EkfNoise",
    "Gate",
    "PlanarEkf",
    "V",
    "W",
    "X",
    "Y",
    "interval_weights",
    "motion_jacobian",
    "motion_model",
    "process_noise",
]


class PlanarEkf(EkfState):
    """EKF over ``[x, y, yaw, v, w, gyro_bias]``; see the module docstring. The state, time line
    and update arithmetic are :class:`~lowerbase.driver.ekf_state.EkfState`'s."""

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
        first, as one measurement of the interval's mean rate. With a ``stamp`` the twist is
        the mean over the interval since the last stamp (as encoder counts over a cycle are):
        the rates are updated first, then the pose is driven over the interval with them.
        """
        if not (math.isfinite(linear) and math.isfinite(angular)):
            return self._count("wheel", Gate.INVALID)
        span = self._begin(stamp, noise=False)
        driven = False
        try:
            gyro = self._gyro_mean(span) if self._gyro_times else None
            bias_considered = not self.is_standstill  # as the gyro finds it, before the wheels
            self._standstill_update(linear, angular)
            if self.noise.gate_gyro or self.is_standstill:
                if span.dt > 0:
                    self._rate_noise(span)
                if gyro is not None:
                    self._gyro(*gyro, bias_considered=bias_considered)
                return self._wheels(linear, angular, covariance)
            try:
                r = self._twist_r(covariance)
            except ValueError:
                if span.dt > 0:
                    self._rate_noise(span)
                if gyro is not None:
                    self._gyro(*gyro, bias_considered=bias_considered)
                raise
            # the usual cycle, moving with an ungated gyro: one compiled call
            kf, n, ws = self.kf, self.noise, self._workspace
            g_rate, g_sigma = gyro if gyro is not None else (0.0, 0.0)
            _, d2, applied = wheel_cycle(
                kf.x, kf.P, ws.data, r, gyro is not None, g_rate, g_sigma**2, bias_considered,
                linear, angular, n.gate_2dof, span.dt, n.max_step, span.frozen,
                n.lateral_slip**2, self._rate_q)
            driven = applied
            if span.dt > 0 and kf.x_prior is not ws.prior[0]:
                kf.x_prior, kf.P_prior = ws.prior
            if gyro is not None:
                self._consecutive["gyro"] = 0
                self._count("gyro", Gate.ACCEPTED)
            self.mahalanobis_sq = d2
            if self.innovation is not ws.wheel[0]:
                self.innovation, self.innovation_covariance = ws.wheel[0], ws.wheel[1]
            # filterpy's y, S, SI, K, z, x_post, P_post: the last applied update's (the views
            # stay in place from one cycle to the next)
            if applied:
                if kf.K is not ws.wheel[3]:
                    kf.y, kf.S, kf.SI, kf.K, kf.z = ws.wheel
                    kf.x_post, kf.P_post = ws.post
                self._consecutive["wheel_linear"] = self._consecutive["wheel_angular"] = 0
                return self._count("wheel", Gate.ACCEPTED)
            if gyro is not None:
                kf.y, kf.S, kf.SI, kf.K, kf.z = ws.gyro
                kf.x_post, kf.P_post = ws.post
            return self._wheels_gated(ws.wheel[4], r, ws.wheel[0], ws.wheel[1])
        finally:
            if not driven:
                self._finish(span)

    def _standstill_update(self, linear: float, angular: float) -> None:
        """Standstill starts when the wheels report no motion, ends when they report any."""
        n = self.noise
        if (
            abs(linear) <= n.standstill_threshold_linear
            and abs(angular) <= n.standstill_threshold_angular
        ):
            if self._still_since is None:
                self._still_since = self._time
        else:
            self._still_since = None

    def _wheels(
        self, linear: float, angular: float, covariance: np.ndarray | tuple[float, ...] | None
    ) -> Gate:
        """The wheels' measurement (the standstill timer already updated)."""
        n = self.noise
        if self.is_standstill:
            self._measure(np.zeros((2, 1)), H_TWIST, self._r_still)
            return self._count("wheel", Gate.STANDSTILL)
        r = self._twist_r(covariance)
        z = np.array([[linear], [angular]])
        _, applied, y, s = self._measure(z, H_TWIST, r, WHEEL_CONSIDER, gate=n.gate_2dof)
        if applied:
            self._consecutive["wheel_linear"] = self._consecutive["wheel_angular"] = 0
            return self._count("wheel", Gate.ACCEPTED)
        return self._wheels_gated(z, r, y, s)

    def _wheels_gated(self, z: np.ndarray, r: np.ndarray, y: np.ndarray, s: np.ndarray) -> Gate:
        """The wheels' twist ``z`` failed the 2-dof gate (innovation ``y``, covariance ``s``):
        use what passes alone."""
        n = self.noise
        v_pass = y.item(0, 0) ** 2 / s.item(0, 0) <= n.gate_1dof
        w_pass = y.item(1, 0) ** 2 / s.item(1, 1) <= n.gate_1dof
        v_ok = v_pass or self._force("wheel_linear")
        w_ok = w_pass or self._force("wheel_angular")
        if v_pass:
            self._consecutive["wheel_linear"] = 0
        if w_pass:
            self._consecutive["wheel_angular"] = 0
        if v_ok and w_ok:  # each plausible alone (jointly marginal), or forced back in
            self._measure(z.copy(), H_TWIST, r, WHEEL_CONSIDER)
            return self._count("wheel", Gate.ACCEPTED if v_pass and w_pass else Gate.FORCED)
        if v_ok:  # slipping wheel: yaw rate out, speed down-weighted
            z1, r1 = z[:1].copy(), r[:1, :1] * n.slip_inflation
            self._measure(z1, H_V, r1, WHEEL_CONSIDER, keep=False)
            return self._count("wheel", Gate.ANGULAR_REJECTED)
        if w_ok:
            z1, r1 = z[1:].copy(), r[1:, 1:].copy()  # contiguous: the kernel's one signature
            self._measure(z1, H_W, r1, WHEEL_CONSIDER, keep=False)
            return self._count("wheel", Gate.LINEAR_REJECTED)
        return self._count("wheel", Gate.REJECTED)

    def update_gyro(
        self, rate: float, stamp: float | None = None, sigma: float | None = None
    ) -> Gate:
        """z-gyro reading ``rate`` [rad/s] (measures ``w + b``), 1-sigma ``sigma`` [rad/s].

        Applied at once, with the samples queued by :meth:`add_gyro`: with a ``stamp``, as
        the trapezoid mean over the interval since the last stamp (see :meth:`add_gyro`)."""
        if not math.isfinite(rate):
            return self._count("gyro", Gate.INVALID)
        sigma = self.noise.gyro_noise if sigma is None else sigma
        if self._gyro_times and sigma != self._gyro_sigma:
            self._fuse_gyro_until(self._gyro_times[-1])
        if stamp is None:
            if self._gyro_times:
                self._flush_gyro(None)
            return self._gyro(rate, sigma)
        self._queue_gyro(rate, stamp, sigma)
        gate = self._fuse_gyro_until(stamp)
        assert gate is not None
        return gate

    def add_gyro(self, rate: float, stamp: float, sigma: float | None = None) -> Gate | None:
        """Queue a z-gyro sample [rad/s] taken at ``stamp`` [s] (1-sigma ``sigma``).

        The samples between two wheel updates are applied as one measurement, their mean with
        variance ``sigma^2 * sum(w_i^2)``, just before the next :meth:`update_wheels` (so the
        filter runs once per wheel cycle, not once per gyro sample). The mean is over the
        wheels' interval, the trapezoid rule on the samples and the last sample of the interval
        before (:func:`~lowerbase.driver.ekf_model.interval_weights`), not the rate of the
        interval before: the heading follows a change of the turn rate without a lag. Samples
        spanning more than ``max_step`` (no wheels: an encoder fault) are applied without
        waiting. Returns ``Gate.INVALID`` for a non-finite sample (dropped), else the gate of a
        measurement applied now, or None when the sample was only queued.
        """
        if not (math.isfinite(rate) and math.isfinite(stamp)):
            return self._count("gyro", Gate.INVALID)
        sigma = self.noise.gyro_noise if sigma is None else sigma
        gate = None
        if self._gyro_times and (sigma != self._gyro_sigma
                                 or stamp - self._gyro_times[0] > self.noise.max_step):
            gate = self._fuse_gyro_until(self._gyro_times[-1])
        self._queue_gyro(rate, stamp, sigma)
        return gate

    @property
    def pending_gyro(self) -> int:
        """Gyro samples queued by :meth:`add_gyro`, not applied yet."""
        return len(self._gyro_times)

    # -- internals ---------------------------------------------------------------------------

    def _queue_gyro(self, rate: float, stamp: float, sigma: float) -> None:
        if not self._gyro_times:
            self._gyro_sigma = sigma
        self._gyro_times.append(float(stamp))
        self._gyro_rates.append(float(rate))

    def _fuse_gyro_until(self, stamp: float) -> Gate | None:
        """The queued samples as the measurement of the interval to ``stamp`` (no wheels)."""
        span = self._begin(stamp)
        try:
            return self._flush_gyro(span) if self._gyro_times else None
        finally:
            self._finish(span)

    def _flush_gyro(self, span: Span | None) -> Gate:
        """Fuse the queued samples (:meth:`_gyro_mean`)."""
        return self._gyro(*self._gyro_mean(span))

    def _gyro_mean(self, span: Span | None) -> tuple[float, float]:
        """Take the queued samples: over ``span`` their trapezoid mean, the last sample fused
        before included; without an interval their plain mean. Returns (mean, its sigma)."""
        times, rates = self._gyro_times, self._gyro_rates  # taken: the queue starts anew
        self._gyro_times, self._gyro_rates = [], []
        prev, self._gyro_prev = self._gyro_prev, (times[-1], rates[-1])
        if span is not None and span.start is not None:
            if prev is not None and prev[0] < times[0]:
                if len(times) == 2:  # the usual cycle, written out (the same bits)
                    mean, squares = interval_mean3(
                        (prev[0], times[0], times[1]), (prev[1], rates[0], rates[1]),
                        span.start, span.start + span.dt)
                    return mean, self._gyro_sigma * math.sqrt(squares)
                times.insert(0, prev[0])
                rates.insert(0, prev[1])
            weights = interval_weight_list(times, span.start, span.start + span.dt)
        else:
            weights = [1.0 / len(times)] * len(times)
        mean = squares = 0.0
        for w_i, r_i in zip(weights, rates, strict=True):
            mean += w_i * r_i
            squares += w_i * w_i
        return mean, self._gyro_sigma * math.sqrt(squares)

    def _gyro(self, rate: float, sigma: float, bias_considered: bool | None = None) -> Gate:
        """The gyro's measurement; the bias a consider state if ``bias_considered`` (default:
        while not at standstill)."""
        r = np.array([[sigma**2]])
        z = np.array([[rate]])
        # The bias is only observable at standstill, where the wheels' zero is exact. While
        # moving, a wheel/gyro disagreement is as likely a wheel radius or slip error as a
        # bias, and letting the bias absorb it turns a wheel error into a heading drift; so
        # the bias is a "consider" state then (its uncertainty counts, its value stays).
        if bias_considered is None:
            bias_considered = not self.is_standstill
        consider = (B,) if bias_considered else ()
        if not self.noise.gate_gyro:
            self._measure(z, H_GYRO, r, consider)
            self._consecutive["gyro"] = 0
            return self._count("gyro", Gate.ACCEPTED)
        d2, applied, _, _ = self._measure(z, H_GYRO, r, consider, gate=self.noise.gate_1dof)
        forced = not applied and d2 > self.noise.gate_1dof  # (a NaN distance is not gated)
        if forced and not self._force("gyro"):
            return self._count("gyro", Gate.REJECTED)
        self._consecutive["gyro"] = 0
        if not applied:
            self._measure(z, H_GYRO, r, consider)
        return self._count("gyro", Gate.FORCED if forced else Gate.ACCEPTED)

    def _twist_r(self, covariance: np.ndarray | tuple[float, ...] | None) -> np.ndarray:
        if covariance is None:
            return self._r_default
        r = np.asarray(covariance, dtype=float).reshape(2, 2)
        if not np.all(np.isfinite(r)) or r[0, 0] <= 0 or r[1, 1] <= 0:
            raise ValueError(f"wheel twist covariance must be finite and positive, got {r}")
        sym: np.ndarray = 0.5 * (r + r.T)
        return sym
