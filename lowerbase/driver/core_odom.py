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


def _wrap32(value: int) -> int:
    """A difference of int32 counts, wrapped into int32's range."""
    return (value + 0x80000000) % 0x100000000 - 0x80000000


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
    _last_counts: tuple[int, int] | None
    _wheels_done: tuple[int, int] | None
    _wheel_speeds: tuple[float, float]
    _wheel_time: float
    _odom_gap: bool

    def _notify(self, what: str) -> None:
        raise NotImplementedError

    def _wheel_gap(self, counter: int, now: float, counts: tuple[int, int]) -> str | None:
        """Why this wheel sample must be a new baseline instead of integrated against the last
        one (None: it is integrated).

        Frames late or lost (no sample for more than ``wheel_gap_cycles``, or a Counter that
        skipped more cycles than the time allows) are only a longer interval: the counts are
        absolute, so the distance and heading in between are integrated, never lost. Only
        counts that restarted near zero (each nearer to 0 than to its last value: a reboot
        whose Heartbeat was lost) and a lost link or a suspected reboot are a new baseline."""
        if self._odom_gap or self.state == LinkState.LOST:
            return "link lost or reboot suspected"
        if self._last_wheel is None:
            return None
        dt = now - self._last_wheel[0]
        cycles = dt / self._wheel_period
        if cycles > self.config.wheel_gap_cycles or \
                (counter - self._last_wheel[1]) % 16 > cycles + 2.0:
            last = self._last_counts
            if last is not None and all(abs(n) < abs(_wrap32(o - n))
                                        for n, o in zip(counts, last, strict=True)):
                return "wheel counts restarted near zero (a reboot whose Heartbeat was lost?)"
            self.stats["wheel_gaps_integrated"] += 1
        return None

    def _wheel_stamp(self, counter: int, now: float) -> float:
        """[s] when this wheel sample was taken, on the sender's time base: the last one's time
        plus the cycles since (:meth:`_cycles`: lost frames are more cycles, not a
        discontinuity), when that disagrees with the receive time ``now`` by more than half a
        cycle (a sender that ran late and now catches up sends its cycles in a burst), never
        after ``now``; back on ``now`` when it falls behind by more than a backlog can be (the
        link timeout). Velocities and the EKF then see the cycles' true spacing,
        not the burst's, and never a speed that the counts over the true interval do not
        give."""
        if self._last_wheel is None or not math.isfinite(self._wheel_time):
            return now
        period = self._wheel_period
        cycles = self._cycles(counter, (now - self._wheel_time) / period)
        stamp = self._wheel_time + cycles * period
        if abs(stamp - now) <= 0.5 * period or stamp > now:
            return now
        if now - stamp > max(self.config.wheel_gap_cycles * period, self.config.link_timeout):
            # further behind than any backlog can be (the link would be lost by then)
            self.stats["wheel_time_reanchored"] += 1
            return now
        self.stats["wheel_late_samples"] += 1
        return stamp

    def _cycles(self, counter: int, since: float) -> int:
        """Wheel cycles since the last sample: of the numbers congruent to the Counter's step
        (modulo its 16) that the receive times allow (at most ``since`` + 2 cycles), the one
        whose wheel speeds are nearest to the last ones (a speed changes little in a cycle; a
        late sample is one cycle on, 16 lost frames are 17: the receive times cannot tell the
        two apart when a backlog comes at once, the counts can); when the wheels stand still,
        the one nearest to the receive times."""
        assert self._last_wheel is not None
        step = (counter - self._last_wheel[1]) % 16
        if step + 16 > since + 2.0 or step + 16 > 16 * 256:
            return step  # the Counter's step is the only candidate (the usual case)
        odo, last, counts = self.odometry, self._last_counts, self._wheels_done
        if odo is None or last is None or counts is None:
            return step
        left = _wrap32(counts[0] - last[0]) * odo.params.metres_per_pulse_left
        right = _wrap32(counts[1] - last[1]) * odo.params.metres_per_pulse_right
        period, (vl, vr) = self._wheel_period, self._wheel_speeds
        best, best_key = step, (math.inf, math.inf)
        k = step
        while k <= max(step, since + 2.0) and k <= 16 * 256:
            if k > 0:
                miss = abs(left / (k * period) - vl) + abs(right / (k * period) - vr)
                key = (round(miss, 6), abs(k - since))
                if key < best_key:
                    best, best_key = k, key
            k += 16
        return best

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
        self._wheels_done = (left[1], right[1])
        gap = self._wheel_gap(left[0], now, (left[1], right[1]))
        stamp = now if gap is not None else self._wheel_stamp(left[0], now)
        self._last_wheel, self._wheel_time = (now, left[0]), stamp
        self._last_counts = (left[1], right[1])
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
        track = odo.params.wheel_distant
        self._wheel_speeds = (odo.linear - odo.angular * track / 2.0,
                              odo.linear + odo.angular * track / 2.0)
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
