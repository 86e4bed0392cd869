"""Motor-shaft encoder counter: pulses = wheel revolutions * ratio * pulse_per_circle.

The exact count is carried as an unbounded integer plus a fractional remainder in [0, 1), so
no pulse is lost however long the robot runs; the reported count is the floor of the exact
value, wrapped to int32 like the hardware register (WheelFeedback.LeftCount/RightCount).

Direction: on our wire BOTH counts increase for forward motion of the base (the firmware
un-mirrors the right motor, which turns the other way on the real robot). Pass
``direction=-1`` to emulate a raw, mirrored counter.
"""

from __future__ import annotations

import math

STATUS_ENCODER_FAULT = 0x4  # WheelFeedback.Left/RightDriverStatus bit 2

_TWO_POW_31 = 1 << 31
_TWO_POW_32 = 1 << 32


def wrap_int32(x: int) -> int:
    """``x`` modulo 2^32 as a signed int32, as a 32-bit hardware counter holds it."""
    return (x + _TWO_POW_31) % _TWO_POW_32 - _TWO_POW_31


def int32_delta(new: int, old: int) -> int:
    """Pulses between two wrapped int32 readings (valid while |true delta| < 2^31)."""
    return wrap_int32(new - old)


class EncoderCounter:
    """Accumulates pulses from wheel angle increments; ``dropout`` freezes the count."""

    def __init__(self, ratio: float, pulse_per_circle: int, direction: int = 1) -> None:
        if direction not in (1, -1):
            raise ValueError(f"direction must be +1 or -1, not {direction}")
        self.ratio = ratio  # gear reduction motor:wheel
        self.pulse_per_circle = pulse_per_circle  # pulses per motor revolution
        self.direction = direction
        self.dropout = False  # injected encoder fault: pulses are lost, the count freezes
        self.total = 0  # unbounded integer count = floor(exact count)
        self._frac = 0.0  # exact count - total, in [0, 1)

    @property
    def count(self) -> int:
        """The int32 register value (wraps at +-2^31)."""
        return wrap_int32(self.total)

    @property
    def exact(self) -> float:
        """Exact accumulated count (for tests; loses precision beyond 2^53)."""
        return self.total + self._frac

    @property
    def status_bits(self) -> int:
        """DriverStatus bit 2 while the encoder is faulty."""
        return STATUS_ENCODER_FAULT if self.dropout else 0

    def pulses_per_wheel_rad(self) -> float:
        """Pulses per radian of wheel rotation = ratio * pulse_per_circle / 2pi."""
        return self.ratio * self.pulse_per_circle / (2.0 * math.pi)

    def add(self, wheel_angle: float) -> int:
        """Add a wheel rotation increment [rad]; returns the change of ``total`` [pulses]."""
        if self.dropout:
            return 0
        x = self._frac + self.direction * wheel_angle * self.pulses_per_wheel_rad()
        n = math.floor(x)
        self._frac = x - n
        if self._frac >= 1.0:  # rounding guard: keep the remainder in [0, 1)
            n, self._frac = n + 1, 0.0
        self.total += n
        return n

    def reset(self, count: int = 0) -> None:
        """Set the counter (a reboot starts the register at 0)."""
        self.total, self._frac = count, 0.0
