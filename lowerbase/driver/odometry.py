"""Wheel odometry of a differential drive from the lower computer's encoder pulse counts.

ROS-free and clock-free: every update takes the sample time as an argument. The integration
follows ros_controllers' diff_drive_controller ``odometry.cpp``: the exact arc for a constant
(linear, angular) step, a second-order Runge-Kutta step when the angular increment is too small
for the arc formula to be well conditioned, no velocity estimate over a too short interval, and
non-finite input ignored.

Conventions (REP-103): x forward, y left, yaw counter-clockwise [rad]. Forward motion of the base
increases both wheel counts (chassis.dbc, WheelFeedback.LeftCount/RightCount).

Covariances are first-order and honest rather than decorative:

* Pose: the dominant odometry errors are systematic (Borenstein's E_d and E_b, plus a common
  scale error; physical-data.md section 5). Each is modelled as an unknown constant with a 1-sigma
  size from :class:`OdometryNoise`; the pose's sensitivity to the three is carried along the path
  and the covariance is ``S diag(k^2) S^T`` plus a small floor. So the position sigma grows in
  proportion to the distance travelled, the heading sigma with distance and with the angle turned
  (never cancelling), and a heading error turns into lateral position error as the robot drives
  on, independently of the update rate.
* Twist: encoder quantisation over the sample interval, the same scale errors applied to the
  current speed, and a floor.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import SupportsIndex

from lowerbase.errors import ConfigError

INT32_MIN = -(1 << 31)
INT32_MAX = (1 << 31) - 1
_UINT32_MASK = (1 << 32) - 1

#: below this angular increment [rad] per step the exact arc is replaced by a Runge-Kutta 2 step
SMALL_ANGULAR_STEP = 1e-6


def wrap_delta_int32(previous: int, current: int) -> int:
    """Signed pulse difference ``current - previous`` of a wrapping int32 counter [pulses].

    The result lies in [-2^31, 2^31): a count going from ``2**31 - 10`` to ``-2**31 + 5`` is
    +15 pulses. Correct as long as the counter moves by less than 2^31 pulses between samples.
    """
    d = (int(current) - int(previous)) & _UINT32_MASK
    return d - (1 << 32) if d > INT32_MAX else d


def normalize_angle(angle: float) -> float:
    """``angle`` [rad] mapped into (-pi, pi]."""
    a = math.remainder(angle, math.tau)
    return math.pi if a == -math.pi else a


def integrate_runge_kutta2(
    x: float, y: float, yaw: float, linear: float, angular: float
) -> tuple[float, float, float]:
    """Second-order step: move ``linear`` [m] along the mid-step heading, turn ``angular`` [rad]."""
    mid = yaw + 0.5 * angular
    return x + linear * math.cos(mid), y + linear * math.sin(mid), yaw + angular


def integrate_exact(
    x: float,
    y: float,
    yaw: float,
    linear: float,
    angular: float,
    small_angular: float = SMALL_ANGULAR_STEP,
) -> tuple[float, float, float]:
    """Exact circular-arc step of arc length ``linear`` [m] and heading change ``angular`` [rad].

    Falls back to :func:`integrate_runge_kutta2` when ``|angular| < small_angular`` [rad], where
    the radius ``linear / angular`` is ill-conditioned; there the two agree to O(angular^2).
    """
    if abs(angular) < small_angular:
        return integrate_runge_kutta2(x, y, yaw, linear, angular)
    r = linear / angular
    yaw_new = yaw + angular
    return (
        x + r * (math.sin(yaw_new) - math.sin(yaw)),
        y - r * (math.cos(yaw_new) - math.cos(yaw)),
        yaw_new,
    )


@dataclass(frozen=True)
class OdometryParameters:
    """Kinematic parameters as the lower computer reports them (ParameterRequest indices 0-4)."""

    #: wheel rim circumference [m] (wheelPerimeter)
    wheel_perimeter: float
    #: distance between the two wheels' contact points, the track [m] (wheelDistant)
    wheel_distant: float
    #: gear reduction, motor revolutions per wheel revolution, left wheel [1] (ratioLeft)
    ratio_left: float
    #: gear reduction, motor revolutions per wheel revolution, right wheel [1] (ratioRight)
    ratio_right: float
    #: encoder pulses per motor revolution [pulses] (pulsePerCircle)
    pulse_per_circle: float

    def __post_init__(self) -> None:
        for name in (
            "wheel_perimeter",
            "wheel_distant",
            "ratio_left",
            "ratio_right",
            "pulse_per_circle",
        ):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ConfigError(
                    f"odometry parameter {name} must be finite and > 0, got {value!r}"
                )

    @cached_property  # read every wheel cycle (frozen: the instance's __dict__ holds it)
    def metres_per_pulse_left(self) -> float:
        """Rim travel of the left wheel per encoder pulse [m]."""
        return self.wheel_perimeter / (self.ratio_left * self.pulse_per_circle)

    @cached_property
    def metres_per_pulse_right(self) -> float:
        """Rim travel of the right wheel per encoder pulse [m]."""
        return self.wheel_perimeter / (self.ratio_right * self.pulse_per_circle)

    @classmethod
    def from_lower_computer(cls, values: Mapping[str, float]) -> OdometryParameters:
        """Build from the lower computer's parameter names (chassis.dbc value table of Index)."""
        try:
            return cls(
                wheel_perimeter=float(values["wheelPerimeter"]),
                wheel_distant=float(values["wheelDistant"]),
                ratio_left=float(values["ratioLeft"]),
                ratio_right=float(values["ratioRight"]),
                pulse_per_circle=float(values["pulsePerCircle"]),
            )
        except KeyError as exc:
            raise ConfigError(f"lower-computer parameter {exc.args[0]} missing") from exc


@dataclass(frozen=True)
class OdometryNoise:
    """1-sigma error model behind the reported covariances (defaults: an uncalibrated base)."""

    #: common scale error of both wheels, as a fraction of distance [m/m] (0.2-1 %)
    scale_error: float = 0.01
    #: heading drift per metre travelled from a wheel-diameter mismatch E_d [rad/m]
    #: (E_d - 1 = 0.5 % on a 0.5 m track gives 0.01 rad/m)
    heading_error_per_metre: float = 0.01
    #: heading error per radian turned from the effective-track error E_b [rad/rad] (0.5-2 %)
    heading_error_per_radian: float = 0.02
    #: pose sigma that is always present: initial pose and unmodelled effects [m]
    position_floor: float = 1e-3
    #: heading sigma that is always present [rad]
    yaw_floor: float = 1e-3
    #: linear velocity sigma that is always present [m/s]
    linear_velocity_floor: float = 2e-3
    #: yaw rate sigma that is always present [rad/s]
    angular_velocity_floor: float = 4e-3
    #: variance reported for the unobserved pose/twist axes (z, roll, pitch) of a 6x6 ROS matrix
    unobserved_variance: float = 1e6

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(f"odometry noise {name} must be finite and >= 0, got {value!r}")


@dataclass(frozen=True)
class OdometryState:
    """Odometry at one instant."""

    #: time of the last encoder sample [s]
    stamp: float
    #: position in the odometry frame [m]
    x: float
    y: float
    #: heading in (-pi, pi] [rad]
    yaw: float
    #: forward velocity of the base [m/s]
    linear: float
    #: yaw rate of the base [rad/s]
    angular: float
    #: covariance of (x, y, yaw), row-major 3x3 [m^2, m*rad, rad^2]
    pose_covariance: tuple[float, ...] = field(repr=False)
    #: covariance of (linear, angular), row-major 2x2 [(m/s)^2, m*rad/s^2, (rad/s)^2]
    twist_covariance: tuple[float, ...] = field(repr=False)

    def ros_pose_covariance(self, unobserved_variance: float = 1e6) -> tuple[float, ...]:
        """The 6x6 row-major (x, y, z, roll, pitch, yaw) matrix of nav_msgs/Odometry."""
        return _embed_planar(self.pose_covariance, 3, (0, 1, 5), unobserved_variance)

    def ros_twist_covariance(self, unobserved_variance: float = 1e6) -> tuple[float, ...]:
        """The 6x6 row-major (vx, vy, vz, wx, wy, wz) matrix of nav_msgs/Odometry.

        vy gets a small variance of its own (a differential drive cannot move sideways),
        the other unobserved axes ``unobserved_variance``.
        """
        m = list(_embed_planar(self.twist_covariance, 2, (0, 5), unobserved_variance))
        m[1 * 6 + 1] = self.twist_covariance[0]  # lateral velocity: known zero, as sure as vx
        return tuple(m)


def _embed_planar(
    cov: tuple[float, ...], n: int, axes: tuple[int, ...], unobserved: float
) -> tuple[float, ...]:
    m = [0.0] * 36
    for i in range(6):
        m[i * 6 + i] = unobserved
    for a, ia in enumerate(axes):
        for b, ib in enumerate(axes):
            m[ia * 6 + ib] = cov[a * n + b]
    return tuple(m)


class WheelOdometry:
    """Integrates wheel encoder counts into pose and twist (diff_drive_controller style).

    Call :meth:`update` with both wheels' raw int32 counts and the sample time [s]. The first
    call only sets the baseline. Counts wrap safely; a jump faster than ``max_wheel_speed``
    [m/s] (a lower-computer reboot that reset its counters) re-baselines instead of teleporting
    the robot. Pose is integrated on every sample; the velocity estimate waits until at least
    ``min_dt`` [s] have passed since the previous estimate.
    """

    def __init__(
        self,
        params: OdometryParameters,
        noise: OdometryNoise | None = None,
        *,
        min_dt: float = 1e-4,
        max_wheel_speed: float = 10.0,
    ) -> None:
        if not (min_dt > 0 and max_wheel_speed > 0):
            raise ConfigError("min_dt and max_wheel_speed must be > 0")
        self.params = params
        self.noise = noise if noise is not None else OdometryNoise()
        self.min_dt = float(min_dt)
        self.max_wheel_speed = float(max_wheel_speed)
        #: updates refused: non-finite stamps, time going backwards, implausible count jumps
        self.rejected_updates = 0
        self.reset()

    # -- state -------------------------------------------------------------------------------

    def reset(self, x: float = 0.0, y: float = 0.0, yaw: float = 0.0) -> None:
        """Set the pose [m, m, rad], zero the velocities and error history, drop the baseline."""
        self._x, self._y, self._yaw = float(x), float(y), float(yaw)
        self._linear = 0.0
        self._angular = 0.0
        self._distance = 0.0
        self._turned = 0.0
        # sensitivity of (x, y, yaw) to (scale, heading/metre, heading/radian) errors
        self._sens = [[0.0, 0.0, 0.0] for _ in range(3)]
        self._twist_var = (0.0, 0.0)
        self.reset_baseline()

    def reset_baseline(self) -> None:
        """Forget the previous counts (the next update only sets the baseline); keep the pose.

        Call it when the lower computer rebooted (Heartbeat.BootCounter changed).
        """
        self._left: int | None = None
        self._right: int | None = None
        self._stamp: float | None = None
        self._vel_stamp: float | None = None
        self._acc_linear = 0.0
        self._acc_angular = 0.0

    def hold(self) -> None:
        """The samples stopped or cannot be trusted (link lost, a gap, a reboot): keep the
        pose, zero the velocities, and take the next sample as a new baseline (its counts are
        not integrated against the old ones)."""
        self.reset_baseline()
        self._linear = self._angular = 0.0
        self._twist_var = (0.0, 0.0)

    @property
    def has_baseline(self) -> bool:
        """True once a first sample has been taken."""
        return self._stamp is not None

    @property
    def x(self) -> float:
        """Position x [m]."""
        return self._x

    @property
    def y(self) -> float:
        """Position y [m]."""
        return self._y

    @property
    def yaw(self) -> float:
        """Heading [rad] in (-pi, pi]."""
        return normalize_angle(self._yaw)

    @property
    def yaw_unwrapped(self) -> float:
        """Heading [rad], continuous (counts full turns)."""
        return self._yaw

    @property
    def linear(self) -> float:
        """Forward velocity [m/s] from the last velocity estimate."""
        return self._linear

    @property
    def angular(self) -> float:
        """Yaw rate [rad/s] from the last velocity estimate."""
        return self._angular

    @property
    def distance_travelled(self) -> float:
        """Path length [m] driven since the last reset (absolute, either direction)."""
        return self._distance

    @property
    def angle_turned(self) -> float:
        """Total absolute heading change [rad] since the last reset."""
        return self._turned

    @property
    def stamp(self) -> float:
        """Time [s] of the last accepted sample (nan before the first)."""
        return math.nan if self._stamp is None else self._stamp

    # -- update ------------------------------------------------------------------------------

    def update(self, left_count: SupportsIndex, right_count: SupportsIndex, stamp: float) -> bool:
        """Take one encoder sample: raw int32 counts [pulses] and its time [s].

        Returns True when the velocity estimate was refreshed. Returns False for the first
        sample, for an interval shorter than ``min_dt`` (pose still integrated), and for
        refused samples (non-finite stamp, time going backwards, implausible jump).
        """
        if not math.isfinite(stamp):
            self.rejected_updates += 1
            return False
        try:
            left, right = operator.index(left_count), operator.index(right_count)
        except TypeError:
            # NaN or fractional counts cannot come from a counter: ignore the sample
            self.rejected_updates += 1
            return False
        if self._stamp is None or self._left is None or self._right is None:
            self._left, self._right = left, right
            self._stamp = self._vel_stamp = float(stamp)
            return False
        dt = stamp - self._stamp
        if dt < 0:
            self.rejected_updates += 1
            return False
        dl = wrap_delta_int32(self._left, left)
        dr = wrap_delta_int32(self._right, right)
        sl = dl * self.params.metres_per_pulse_left
        sr = dr * self.params.metres_per_pulse_right
        # a reboot that zeroed the counters, or garbage: too fast for the wheel
        limit = self.max_wheel_speed * max(dt, 0.01)
        if abs(sl) > limit or abs(sr) > limit:
            self.rejected_updates += 1
            self.reset_baseline()
            self._left, self._right = left, right
            self._stamp = self._vel_stamp = float(stamp)
            return False
        self._left, self._right = left, right
        self._stamp = float(stamp)
        self.integrate(0.5 * (sr + sl), (sr - sl) / self.params.wheel_distant)

        assert self._vel_stamp is not None
        vel_dt = stamp - self._vel_stamp
        if vel_dt < self.min_dt:
            return False
        self._linear = self._acc_linear / vel_dt
        self._angular = self._acc_angular / vel_dt
        self._twist_var = self._twist_variance(vel_dt)
        self._acc_linear = self._acc_angular = 0.0
        self._vel_stamp = float(stamp)
        return True

    def integrate(self, linear: float, angular: float) -> None:
        """Advance the pose by an arc of length ``linear`` [m] and heading change ``angular`` [rad].

        Non-finite increments are ignored. Also carries the error sensitivities along.
        """
        if not (math.isfinite(linear) and math.isfinite(angular)):
            self.rejected_updates += 1
            return
        yaw0 = self._yaw
        self._x, self._y, self._yaw = integrate_exact(self._x, self._y, yaw0, linear, angular)
        self._distance += abs(linear)
        self._turned += abs(angular)
        self._acc_linear += linear
        self._acc_angular += angular
        self._propagate_sensitivity(yaw0, linear, angular)

    # -- covariance --------------------------------------------------------------------------

    def _propagate_sensitivity(self, yaw0: float, ds: float, dyaw: float) -> None:
        # Perturbed step: ds' = ds (1 + e_s), dyaw' = dyaw + e_d |ds| + e_r |dyaw|. The heading
        # terms take magnitudes: a pure E_d or E_b error would cancel when driving back or
        # turning the other way, but the real errors change with load and floor, so claiming
        # that cancellation would be overconfident.
        sx, sy, syaw = self._sens
        a_ds, a_dyaw = abs(ds), abs(dyaw)  # dyaw_de = (0, |ds|, |dyaw|); dds = (ds, 0, 0)
        mid = yaw0 + 0.5 * dyaw
        c, s = math.cos(mid), math.sin(mid)
        m0, m1, m2 = syaw[0] + 0.5 * 0.0, syaw[1] + 0.5 * a_ds, syaw[2] + 0.5 * a_dyaw
        dsc, dss = ds * c, ds * s
        # written out (the same operations as the loop over j): this runs every wheel cycle
        self._sens = [
            [sx[0] + ds * c - dss * m0, sx[1] + 0.0 * c - dss * m1, sx[2] + 0.0 * c - dss * m2],
            [sy[0] + ds * s + dsc * m0, sy[1] + 0.0 * s + dsc * m1, sy[2] + 0.0 * s + dsc * m2],
            [syaw[0] + 0.0, syaw[1] + a_ds, syaw[2] + a_dyaw],
        ]

    @property
    def pose_covariance(self) -> tuple[float, ...]:
        """Covariance of (x, y, yaw), row-major 3x3 [m^2, m*rad, rad^2]."""
        n = self.noise
        k2 = (n.scale_error**2, n.heading_error_per_metre**2, n.heading_error_per_radian**2)
        sens = self._sens
        floor = (n.position_floor**2, n.position_floor**2, n.yaw_floor**2)
        out = []
        for i in range(3):
            for j in range(3):
                v = sum(sens[i][k] * sens[j][k] * k2[k] for k in range(3))
                out.append(v + (floor[i] if i == j else 0.0))
        return tuple(out)

    def _twist_variance(self, dt: float) -> tuple[float, float]:
        p, n = self.params, self.noise
        # a count difference of two quantised readings: uniform +-1/2 pulse at each end
        q_l = p.metres_per_pulse_left**2 / 6.0 / dt**2
        q_r = p.metres_per_pulse_right**2 / 6.0 / dt**2
        v, w = self._linear, self._angular
        var_v = 0.25 * (q_l + q_r) + (n.scale_error * v) ** 2 + n.linear_velocity_floor**2
        var_w = (
            (q_l + q_r) / p.wheel_distant**2
            + (n.heading_error_per_metre * v) ** 2
            + (n.heading_error_per_radian * w) ** 2
            + n.angular_velocity_floor**2
        )
        return var_v, var_w

    @property
    def twist_covariance(self) -> tuple[float, ...]:
        """Covariance of (linear, angular), row-major 2x2 [(m/s)^2, ..., (rad/s)^2]."""
        var_v, var_w = self._twist_var
        if var_v == 0.0:  # no estimate yet: the floors alone
            var_v = self.noise.linear_velocity_floor**2
            var_w = self.noise.angular_velocity_floor**2
        return (var_v, 0.0, 0.0, var_w)

    def state(self) -> OdometryState:
        """Snapshot of pose, twist and covariances."""
        return OdometryState(
            stamp=self.stamp,
            x=self._x,
            y=self._y,
            yaw=self.yaw,
            linear=self._linear,
            angular=self._angular,
            pose_covariance=self.pose_covariance,
            twist_covariance=self.twist_covariance,
        )
