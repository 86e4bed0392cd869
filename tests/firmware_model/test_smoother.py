"""Velocity smoother: separate accel and decel limits, exact within a step."""

from __future__ import annotations

import pytest

from lowerbase.firmware_model.profile import ChassisParams
from lowerbase.firmware_model.smoother import SmootherLimits, VelocitySmoother, ramp

LIMITS = SmootherLimits.from_chassis(ChassisParams())  # 0.8 / 1.0 m/s^2, 1.5 / 2.0 rad/s^2


def run(smoother: VelocitySmoother, v: float, w: float, seconds: float, dt: float = 0.005) -> None:
    for _ in range(round(seconds / dt)):
        smoother.step(v, w, dt)


def test_accelerates_at_the_accel_limit_until_the_target() -> None:
    s = VelocitySmoother(LIMITS)
    run(s, 1.0, 0.0, 0.5)
    assert s.v == pytest.approx(0.8 * 0.5)
    run(s, 1.0, 0.0, 0.75)  # 1.25 s in total: 0.8 * 1.25 = 1.0 reached
    assert s.v == pytest.approx(1.0)
    run(s, 1.0, 0.0, 1.0)
    assert s.v == 1.0


def test_decelerates_at_the_decel_limit() -> None:
    s = VelocitySmoother(LIMITS, v=1.0, w=-1.0)
    run(s, 0.0, 0.0, 0.3)
    assert s.v == pytest.approx(1.0 - 1.0 * 0.3)
    assert s.w == pytest.approx(-1.0 + 2.0 * 0.3)
    run(s, 0.2, 0.0, 0.6)  # 0.7 -> 0.2 (0.5 s at 1.0), then hold
    assert s.v == pytest.approx(0.2) and s.w == 0.0


def test_sign_flip_brakes_to_zero_then_accelerates() -> None:
    s = VelocitySmoother(LIMITS, v=0.5)
    run(s, -0.5, 0.0, 0.75)  # 0.5 s braking at 1.0, then 0.25 s accelerating at 0.8
    assert s.v == pytest.approx(-0.8 * 0.25)


def test_result_does_not_depend_on_the_step_size() -> None:
    fine, coarse = VelocitySmoother(LIMITS, v=0.5, w=0.3), VelocitySmoother(LIMITS, v=0.5, w=0.3)
    run(fine, -0.5, -1.0, 0.75, dt=0.001)
    coarse.step(-0.5, -1.0, 0.75)
    assert fine.v == pytest.approx(coarse.v) and fine.w == pytest.approx(coarse.w)


def test_ramp_edge_cases() -> None:
    assert ramp(0.3, 1.0, 1.0, 1.0, 0.0) == 0.3  # no time, no change
    assert ramp(0.3, 1.0, 1.0, 1.0, -1.0) == 0.3
    assert ramp(-0.1, 0.0, 5.0, 1.0, 0.05) == pytest.approx(-0.05)  # decel toward zero
    s = VelocitySmoother(LIMITS, v=1.0, w=1.0)
    s.reset()
    assert (s.v, s.w) == (0.0, 0.0)
