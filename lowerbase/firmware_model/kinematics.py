"""Differential-drive kinematics and the MCU's hard velocity limits, as small pure functions.

Conventions (REP-103): v [m/s] forward, w [rad/s] counter-clockwise; rim speeds [m/s] are
forward-positive for both wheels; wheel speeds [rad/s] likewise; motor speeds in rpm.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

from lowerbase.firmware_model.profile import ChassisParams

Side = Literal["left", "right"]
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)  # 1 rad/s = 9.549 rpm


def wheel_speeds_from_twist(v: float, w: float, track: float) -> tuple[float, float]:
    """Inverse kinematics: base twist (v [m/s], w [rad/s]) -> rim speeds (left, right) [m/s]."""
    half = 0.5 * w * track
    return v - half, v + half


def twist_from_wheel_speeds(v_left: float, v_right: float, track: float) -> tuple[float, float]:
    """Forward kinematics: rim speeds [m/s] -> base twist (v [m/s], w [rad/s])."""
    return 0.5 * (v_left + v_right), (v_right - v_left) / track


def rim_speed_to_wheel_rad_s(rim_m_s: float, perimeter: float) -> float:
    """Rim speed [m/s] -> wheel angular velocity [rad/s] for a wheel of ``perimeter`` [m]."""
    return rim_m_s * 2.0 * math.pi / perimeter


def wheel_rad_s_to_rim_speed(wheel_rad_s: float, perimeter: float) -> float:
    """Wheel angular velocity [rad/s] -> rim speed [m/s]."""
    return wheel_rad_s * perimeter / (2.0 * math.pi)


def wheel_rad_s_to_motor_rpm(wheel_rad_s: float, ratio: float) -> float:
    """Wheel angular velocity [rad/s] -> motor speed [rpm] via gear ``ratio`` (motor:wheel)."""
    return wheel_rad_s * ratio * RPM_PER_RAD_S


def motor_rpm_to_wheel_rad_s(motor_rpm: float, ratio: float) -> float:
    """Motor speed [rpm] -> wheel angular velocity [rad/s]."""
    return motor_rpm / (ratio * RPM_PER_RAD_S)


def max_rim_speed(params: ChassisParams, side: Side) -> float:
    """Highest rim speed [m/s] of one wheel: maxSpeed, or maxRPM through its ratio if lower."""
    ratio = params.ratio_left if side == "left" else params.ratio_right
    at_rpm = wheel_rad_s_to_rim_speed(
        motor_rpm_to_wheel_rad_s(params.max_rpm, ratio), params.wheel_perimeter
    )
    return min(params.max_speed, at_rpm)


class LimitedTwist(NamedTuple):
    """Result of :func:`limit_twist`.

    ``valid`` is False when the request held NaN or an infinity: v and w are then 0 and the
    MCU should reject the command (and flag it) rather than drive.
    """

    v: float  # [m/s]
    w: float  # [rad/s]
    clipped: bool  # any limit changed the request
    valid: bool = True


def limit_twist(v: float, w: float, params: ChassisParams) -> LimitedTwist:
    """Apply the hard limits of the lower computer to a requested twist.

    |v| is clipped to maxLinear and |w| to maxAngular independently (as diff_drive_controller's
    speed limiter does). If a wheel would then exceed its rim-speed limit (maxSpeed, or maxRPM
    through its ratio), BOTH wheel speeds are scaled by the same factor, so the path curvature
    w/v is preserved and only the speed along it drops.
    """
    if not (math.isfinite(v) and math.isfinite(w)):
        return LimitedTwist(0.0, 0.0, clipped=True, valid=False)
    v_c = min(max(v, -params.max_linear), params.max_linear)
    w_c = min(max(w, -params.max_angular), params.max_angular)
    v_l, v_r = wheel_speeds_from_twist(v_c, w_c, params.wheel_distant)
    excess = max(
        abs(v_l) / max_rim_speed(params, "left"), abs(v_r) / max_rim_speed(params, "right")
    )
    if excess > 1.0:
        v_c, w_c = v_c / excess, w_c / excess
    return LimitedTwist(v_c, w_c, clipped=(v_c != v or w_c != w))
