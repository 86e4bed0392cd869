"""Wheel odometry and gyro input of :class:`~lowerbase.driver.core.DriverCore`: a wheel
sample pair integrated (/odom_raw) and fused (/odom), stamped on the sender's time base; gaps,
lost links and suspected reboots held as a new baseline, not motion."""

from __future__ import annotations

import logging
import math
from collections import Counter
from typing import Any

from lowerbase.driver.core_defs import _IMU_FAULT, DriverConfig, LinkState
from lowerbase.driver.ekf import PlanarEkf
from lowerbase.driver.odometry import WheelOdometry

log = logging.getLogger("lowerbase.driver.core")


class OdometryInput:
    """DriverCore's wheel and gyro frames: /odom_raw and the EKF fed, gaps held (a mixin)."""

    state: LinkState
    config: DriverConfig
    stats: Counter[str]
    ekf: PlanarEkf
    odometry: WheelOdometry | None
    parameters: dict[str, float]
    status_code: int
    imu: tuple[tuple[float, float, float], tuple[float, float, float]] | None
    imu_stamp: float
    _wheels: dict[int, tuple[int, int]]
    _wheel_period: float
    _last_wheel: tuple[float, int] | None
    _wheel_time: float
    _odom_gap: bool

    def _notify(self, what: str) -> None:
        raise NotImplementedError

    def _wheel_gap(self, counter: int, now: float) -> str | None:
        """Why this wheel sample must not be integrated against the last one (None: it may)."""
        if self._odom_gap or self.state == LinkState.LOST:
            return "link lost or reboot suspected"
        if self._last_wheel is None:
            return None
        dt = now - self._last_wheel[0]
        cycles = dt / self._wheel_period
        if cycles > self.config.wheel_gap_cycles:
            return f"no wheel sample for {dt:.2f} s"
        if (counter - self._last_wheel[1]) % 16 > cycles + 2.0:
            # more cycles than the time allows; fewer is a late sender (it catches up next)
            return "WheelFeedback Counter discontinuity"
        return None

    def _wheel_stamp(self, counter: int, now: float) -> float:
        """[s] when this wheel sample was taken, on the sender's time base: the last one's time
        plus the Counter's cycles, when that disagrees with the receive time ``now`` by more than
        half a cycle (a sender that ran late and now catches up sends its cycles in a burst),
        never after ``now``; back on ``now`` when it falls behind by more than the gap limit (a
        sender whose clock runs slow). Velocities and the EKF then see the cycles' true spacing,
        not the burst's."""
        if self._last_wheel is None or not math.isfinite(self._wheel_time):
            return now
        period = self._wheel_period
        stamp = self._wheel_time + (counter - self._last_wheel[1]) % 16 * period
        if abs(stamp - now) <= 0.5 * period or stamp > now:
            return now
        if now - stamp > self.config.wheel_gap_cycles * period:
            self.stats["wheel_time_reanchored"] += 1
            return now
        self.stats["wheel_late_samples"] += 1
        return stamp

    def _watchdog_time(self) -> float:
        """[s] how long the base may go on moving unseen: its watchdog, then braking."""
        v = abs(self.ekf.twist[0])
        decel = max(self.parameters.get("linearDecelLimit", 1.0), 0.1)
        return self.parameters.get("commandTimeout", 0.5) + v / (2.0 * decel)

    def _hold_odometry(self, unknown_time: float) -> None:
        """Stop integrating: hold both poses, zero the velocities, re-baseline the next
        sample. The base may move ``unknown_time`` [s] unseen: the EKF's pose variance says so."""
        self._odom_gap = True
        if self.odometry is not None:
            self.odometry.hold()
        v, w = self.ekf.twist
        self.ekf.hold(abs(v) * unknown_time, abs(w) * unknown_time)

    def _on_WheelFeedback(self, v: dict[str, Any], now: float) -> None:
        wheel = int(v["Wheel"])  # the multiplexer: LeftCount or RightCount
        self._wheels[wheel] = (int(v["Counter"]), int(v["RightCount" if wheel else "LeftCount"]))
        left, right = self._wheels.get(0), self._wheels.get(1)
        if left is None or right is None or left[0] != right[0] or self.odometry is None:
            return  # wait for both wheels of the same cycle
        self._wheels = {}
        odo = self.odometry
        gap = self._wheel_gap(left[0], now)
        stamp = now if gap is not None else self._wheel_stamp(left[0], now)
        self._last_wheel, self._wheel_time = (now, left[0]), stamp
        if gap is not None:
            # counts after a gap may come from restarted counters: a new baseline, no motion
            self.stats["odometry_rebaselined"] += 1
            log.info("wheel odometry re-baselined: %s", gap)
            if not self._odom_gap:  # else held already, when the gap began
                self._hold_odometry(0.0)
            odo.hold()
            odo.update(left[1], right[1], stamp)
            self._odom_gap = self.state == LinkState.LOST
            return
        if not odo.update(left[1], right[1], stamp):
            return
        # The EKF weighs the wheels with its own model of their errors (EkfNoise.wheel_*):
        # radius and track errors and slip, which /odom_raw's quantisation-based twist
        # covariance does not contain; with that one the wheels would outvote the gyro.
        self.ekf.update_wheels(odo.linear, odo.angular, stamp=stamp)
        self._notify("odometry")

    def _on_ImuGyro(self, v: dict[str, Any], now: float) -> None:
        gyro = (float(v["X"]), float(v["Y"]), float(v["Z"]))
        accel = self.imu[1] if self.imu is not None else (0.0, 0.0, 0.0)
        self.imu = (gyro, accel)
        self.imu_stamp = now
        if self.odometry is not None and not self.status_code & _IMU_FAULT and \
                not self._odom_gap:
            # the gyro is the EKF's yaw-rate reference; once the lower computer flags the
            # IMU as faulty (frozen output) the EKF runs on the wheels alone. The samples
            # are queued and fused as one with the next wheel update (one EKF step per cycle)
            self.ekf.add_gyro(gyro[2], now, sigma=self.config.gyro_sigma)
