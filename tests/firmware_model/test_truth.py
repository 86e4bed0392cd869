"""Ground truth: exact arcs, radius/track errors, slip events."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.firmware_model.profile import ChassisParams, TruthParams
from lowerbase.firmware_model.truth import (
    GroundTruth,
    SlipEvent,
    SlipModel,
    TrueGeometry,
    integrate_pose,
)

R = 0.1  # [m] wheel radius
TRACK = 0.5  # [m]
IDEAL = TrueGeometry(R, R, TRACK)


def drive(truth: GroundTruth, v: float, w: float, seconds: float, dt: float = 0.005) -> None:
    omega_l, omega_r = (v - w * TRACK / 2) / R, (v + w * TRACK / 2) / R
    for _ in range(round(seconds / dt)):
        truth.step(omega_l, omega_r, dt)


def test_straight_line() -> None:
    truth = GroundTruth(IDEAL, yaw=math.pi / 6)
    drive(truth, 0.8, 0.0, 5.0)
    assert truth.x == pytest.approx(4.0 * math.cos(math.pi / 6))
    assert truth.y == pytest.approx(4.0 * math.sin(math.pi / 6))
    assert truth.yaw == math.pi / 6 and truth.distance == pytest.approx(4.0)


def test_rotation_in_place_gives_yaw_w_t() -> None:
    truth = GroundTruth(IDEAL)
    drive(truth, 0.0, 0.9, 4.0)
    assert truth.yaw == pytest.approx(0.9 * 4.0)
    assert (truth.x, truth.y, truth.distance) == (0.0, 0.0, 0.0)


def test_arc_matches_the_closed_form_circle() -> None:
    v, w = 0.6, 0.4  # radius 1.5 m
    truth = GroundTruth(IDEAL)
    drive(truth, v, w, 3.0, dt=0.02)
    assert truth.x == pytest.approx(v / w * math.sin(w * 3.0), abs=1e-12)
    assert truth.y == pytest.approx(v / w * (1 - math.cos(w * 3.0)), abs=1e-12)
    drive(truth, v, w, 2 * math.pi / w - 3.0, dt=(2 * math.pi / w - 3.0) / 1000)
    assert (truth.x, truth.y) == pytest.approx((0.0, 0.0), abs=1e-9)  # full circle
    assert truth.body_accel == pytest.approx((0.0, v * w, 0.0))
    assert truth.body_omega == pytest.approx((0.0, 0.0, w))


def test_one_big_step_equals_many_small_ones() -> None:
    assert integrate_pose(1.0, 2.0, 0.3, 0.5, 0.2, 10.0) == pytest.approx(
        (
            1.0 + 2.5 * (math.sin(2.3) - math.sin(0.3)),
            2.0 - 2.5 * (math.cos(2.3) - math.cos(0.3)),
            2.3,
        )
    )
    tiny_w = integrate_pose(0.0, 0.0, 0.0, 1.0, 1e-9, 1.0)
    assert tiny_w == pytest.approx((1.0, 0.5e-9, 1e-9), rel=1e-12, abs=1e-15)


def test_radius_and_track_errors() -> None:
    geometry = TrueGeometry.from_profile(
        ChassisParams(),
        TruthParams(left_radius_error=0.0, right_radius_error=0.01, track_error=0.02),
    )
    r = 0.6283 / (2 * math.pi)
    assert geometry.radius_left == pytest.approx(r)
    assert geometry.radius_right == pytest.approx(r * 1.01)
    assert geometry.track == pytest.approx(0.51)
    truth = GroundTruth(geometry)
    truth.step(10.0, 10.0, 1.0)  # same wheel speed: the larger right wheel turns the robot left
    assert truth.w == pytest.approx(10.0 * r * 0.01 / 0.51)
    assert truth.v == pytest.approx(10.0 * r * 1.005)


def test_slip_reduces_ground_speed() -> None:
    truth = GroundTruth(IDEAL)
    truth.step(10.0, 10.0, 0.5, slip=(1.0, 0.0))  # left wheel spins freely: pivot about it
    assert truth.v == pytest.approx(0.5) and truth.w == pytest.approx(1.0 / TRACK)
    assert truth.accel_x == pytest.approx(0.5 / 0.5)


def test_slip_event_window() -> None:
    event = SlipEvent("right", start=2.0, duration=0.25, fraction=0.4)
    assert event.fractions(1.99) == (0.0, 0.0)
    assert event.fractions(2.0) == (0.0, 0.4) and event.fractions(2.2) == (0.0, 0.4)
    assert event.fractions(2.25) == (0.0, 0.0)
    assert SlipEvent("both", 0.0, 1.0, 0.1).fractions(0.5) == (0.1, 0.1)


def test_slip_model_events_and_acceleration_slip() -> None:
    model = SlipModel(TruthParams(accel_slip_threshold=2.0, accel_slip_fraction=0.05))
    model.add_event(SlipEvent("left", 1.0, 0.5, 0.3))
    assert model.step(0.5, 0.01) == (0.0, 0.0)
    assert model.step(1.2, 0.01, rim_accel=(0.0, -2.5)) == (0.3, 0.05)
    assert model.step(1.6, 0.01) == (0.0, 0.0) and model.events == []


def test_random_slip_events_follow_the_rate_per_distance() -> None:
    params = TruthParams(slip_rate_per_km=100.0, slip_duration=0.1, slip_fraction=0.5)
    model = SlipModel(params, np.random.default_rng(5))
    slipping = sum(model.step(t, 1.0) != (0.0, 0.0) for t in range(10_000))  # 1 m per second
    assert slipping == pytest.approx(100 * 10, rel=0.15)  # 100/km over 10 km
    assert SlipModel(TruthParams()).step(0.0, 1e6) == (0.0, 0.0)  # none by default
