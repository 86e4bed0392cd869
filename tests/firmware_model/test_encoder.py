"""Encoder counts: exact pulses for closed-form motions, int32 wrap, dropout."""

from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from lowerbase.firmware_model.encoder import (
    STATUS_ENCODER_FAULT,
    EncoderCounter,
    int32_delta,
    wrap_int32,
)
from lowerbase.firmware_model.kinematics import rim_speed_to_wheel_rad_s, wheel_speeds_from_twist
from lowerbase.firmware_model.motor import WheelGeometry, WheelMotor
from lowerbase.firmware_model.profile import ChassisParams, MotorParams

CHASSIS = ChassisParams()  # perimeter 0.6283 m, ratio 20, 10000 pulses per motor revolution
IDEAL = MotorParams(time_constant=0.0, max_wheel_accel=0.0)


def drive(v: float, w: float, seconds: float, dt: float = 0.005) -> tuple[int, int]:
    """Counts after driving the ideal motors at twist (v, w): firmware path, nominal geometry."""
    counters = [EncoderCounter(CHASSIS.ratio_left, CHASSIS.pulse_per_circle) for _ in range(2)]
    motors = [WheelMotor(IDEAL, WheelGeometry.from_chassis(CHASSIS, s)) for s in ("left", "right")]
    rims = wheel_speeds_from_twist(v, w, CHASSIS.wheel_distant)
    for _ in range(round(seconds / dt)):
        for motor, counter, rim in zip(motors, counters, rims, strict=True):
            counter.add(motor.step(rim_speed_to_wheel_rad_s(rim, CHASSIS.wheel_perimeter), dt))
    return counters[0].count, counters[1].count


def test_straight_line_gives_the_predicted_pulses() -> None:
    v, t = 0.73, 12.0
    expected = math.floor(v * t / 0.6283 * 20 * 10000)  # 2 788 476.8...
    assert drive(v, 0.0, t) == (expected, expected)


def test_rotation_in_place_counts_opposite() -> None:
    w, t = 0.9, 3.0
    rim = w * CHASSIS.wheel_distant / 2
    pulses = rim * t / 0.6283 * 20 * 10000  # 214 865.5...
    assert drive(0.0, w, t) == (math.floor(-pulses), math.floor(pulses))


def test_fractions_are_carried_not_lost() -> None:
    counter = EncoderCounter(ratio=1.0, pulse_per_circle=4)  # 4 pulses per wheel revolution
    quarter_pulse = 2 * math.pi / 16
    steps = [counter.add(quarter_pulse) for _ in range(40_000)]
    assert counter.total == 10_000 and sum(steps) == 10_000
    assert max(steps) == 1 and counter.exact == 10_000
    counter.add(-quarter_pulse)  # 9999.75 -> floor 9999
    assert counter.total == 9_999


def test_direction_and_dropout() -> None:
    mirrored = EncoderCounter(20.0, 10000, direction=-1)
    mirrored.add(2 * math.pi)  # one forward wheel revolution
    assert mirrored.count == -200_000
    counter = EncoderCounter(20.0, 10000)
    counter.add(math.pi)
    counter.dropout = True
    assert counter.add(math.pi) == 0 and counter.count == 100_000
    assert counter.status_bits == STATUS_ENCODER_FAULT
    counter.dropout = False
    counter.add(math.pi)  # the pulses during the dropout are lost
    assert counter.count == 200_000 and counter.status_bits == 0


def test_count_wraps_like_a_32_bit_register() -> None:
    counter = EncoderCounter(1.0, 1000)
    counter.reset(2**31 - 10)
    before = counter.count
    counter.add(2 * math.pi * 0.02)  # +20 pulses
    assert counter.count == -(2**31) + 10
    assert int32_delta(counter.count, before) == 20


def test_an_hour_past_the_wrap_unwraps_to_the_exact_total() -> None:
    # 3000 rpm motor = 500 000 pulses/s wraps the int32 after 72 min; read it at 10 Hz for 80 min
    counter = EncoderCounter(CHASSIS.ratio_left, CHASSIS.pulse_per_circle)
    wheel = rim_speed_to_wheel_rad_s(1.5432, CHASSIS.wheel_perimeter)
    unwrapped, last, wrapped = 0, counter.count, False
    for _ in range(80 * 60 * 10):
        counter.add(wheel * 0.1)
        unwrapped += int32_delta(counter.count, last)
        wrapped = wrapped or counter.count < last
        last = counter.count
    assert wrapped
    exact = 1.5432 * 4800 / 0.6283 * 20 * 10000
    assert unwrapped == counter.total
    assert abs(counter.exact - exact) < 1e-3  # no pulse lost over 80 minutes


@given(st.integers(-(2**70), 2**70))
def test_wrap_int32_is_modulo_2_pow_32(x: int) -> None:
    y = wrap_int32(x)
    assert -(2**31) <= y < 2**31 and (x - y) % 2**32 == 0
