"""Acceleration-limited velocity smoother for the base twist (MotionCommand Mode = Smoothed).

Linear and angular velocity are limited independently, each with its own acceleration limit
(while |x| grows) and deceleration limit (while |x| shrinks, including the part of a sign flip
before zero). Within one step the motion is solved exactly: a flip that reaches zero mid-step
spends the rest of the step accelerating, so results do not depend on the step size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from lowerbase.firmware_model.profile import ChassisParams


@dataclass(frozen=True)
class SmootherLimits:
    """Acceleration limits, all > 0: [m/s^2] for linear, [rad/s^2] for angular."""

    linear_accel: float
    linear_decel: float
    angular_accel: float
    angular_decel: float

    @classmethod
    def from_chassis(cls, chassis: ChassisParams) -> SmootherLimits:
        """The limits held in the chassis parameters (linearAccelLimit, ...)."""
        return cls(
            chassis.linear_accel_limit,
            chassis.linear_decel_limit,
            chassis.angular_accel_limit,
            chassis.angular_decel_limit,
        )


def ramp(current: float, target: float, accel: float, decel: float, dt: float) -> float:
    """Move ``current`` toward ``target`` for ``dt`` [s] at rate ``accel`` while |x| grows and
    ``decel`` while |x| shrinks (units: those of x per second)."""
    if dt <= 0.0 or current == target:
        return current
    if current * target < 0.0:  # sign flip: brake to zero first, then accelerate with the rest
        t_zero = abs(current) / decel
        if t_zero >= dt:
            return current - math.copysign(decel * dt, current)
        current, dt = 0.0, dt - t_zero
    shrinking = abs(target) < abs(current) and current * target >= 0.0
    rate = decel if shrinking else accel
    step = rate * dt
    if abs(target - current) <= step:
        return target
    return current + math.copysign(step, target - current)


class VelocitySmoother:
    """Stateful smoother: ``step(target_v, target_w, dt) -> (v, w)``; no clock, ``dt`` given."""

    def __init__(self, limits: SmootherLimits, v: float = 0.0, w: float = 0.0) -> None:
        self.limits = limits  # replace to apply new parameters; the state is kept
        self.v = v  # [m/s] current smoothed linear velocity
        self.w = w  # [rad/s] current smoothed angular velocity

    def step(self, target_v: float, target_w: float, dt: float) -> tuple[float, float]:
        """Advance by ``dt`` [s] toward (target_v [m/s], target_w [rad/s]); returns (v, w)."""
        lim = self.limits
        self.v = ramp(self.v, target_v, lim.linear_accel, lim.linear_decel, dt)
        self.w = ramp(self.w, target_w, lim.angular_accel, lim.angular_decel, dt)
        return self.v, self.w

    def reset(self, v: float = 0.0, w: float = 0.0) -> None:
        """Set the state, e.g. to the measured twist after an e-stop or on mode change."""
        self.v, self.w = v, w
