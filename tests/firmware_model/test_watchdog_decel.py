"""The watchdog stop's deceleration, on the simulated clock.

Commands stop while driving Smoothed (MotionCommand Mode = smoothed): the chassis slows down at
the configured linearDecelLimit / angularDecelLimit (as ROS diff_drive_controller's limiter does
on a command timeout), then holds with the brake. Raw commands, e-stops and faults brake at the
motor's limit (max_wheel_accel at the rim). Closed forms: from speed v at deceleration a the
base stops after v / a and v^2 / (2a); the firmware's minSpeed deadband (rim speeds below it
are dropped to zero at once) ends the ramp that much early: (v - deadband) / a.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import pytest

from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import Profile, load_profile
from lowerbase.firmware_model.sim import SimRig
from lowerbase.protocol.status_codes import StatusBit


@pytest.fixture(autouse=True, params=["lean", "hooked"])
def control_loop(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test both ways: the period without the fault hooks (fastloop.py) and with them
    checked in every period."""
    monkeypatch.setattr(Mcu, "lean", request.param == "lean", raising=False)


def exact_profile(**chassis: float) -> Profile:
    """No velocity-loop lag, no noise, no geometry error or slip; the driver's ramp
    (max_wheel_accel) is kept: it is the motor limit the raw stop brakes at."""
    p = load_profile()
    return p.replace(
        chassis=dataclasses.replace(p.chassis, **chassis),
        motor=dataclasses.replace(p.motor, time_constant=0.0),
        imu=dataclasses.replace(p.imu, noise=False),
        truth=dataclasses.replace(p.truth, left_radius_error=0.0, right_radius_error=0.0,
                                  track_error=0.0),
    )


@dataclass
class Stop:
    fired: float  #: [s] after the last MotionCommand: the step WATCHDOG_STOP was first set
    duration: float  #: [s] from the start of that step to both wheels at rest
    distance: float  #: [m] travelled by the base centre meanwhile (truth)
    turned: float  #: [rad] yaw turned meanwhile (truth)


def watchdog_stop(rig: SimRig, linear: float, angular: float, smoothed: bool) -> Stop:
    """Drive (long enough to reach the speed), stop commanding, step until standstill."""
    rig.enable()
    rig.drive(linear, angular, 3.0, smoothed=smoothed)
    t_last = rig.now - 0.02  # drive() sends every 20 ms: the last one went 20 ms ago
    mcu, truth = rig.mcu, rig.mcu.truth
    start: tuple[float, float, float] | None = None
    for _ in range(round(5.0 / mcu.dt)):
        before = (rig.now, truth.x, truth.yaw)
        rig.step()
        if start is None and mcu.status & StatusBit.WATCHDOG_STOP:
            start = before
        if start is not None and all(m.omega == 0.0 for m in mcu.motors.values()):
            return Stop(start[0] - t_last, rig.now - start[0], truth.x - start[1],
                        truth.yaw - start[2])
    raise AssertionError("not at rest 5 s after the last command")


def test_smoothed_watchdog_stop_decelerates_at_linear_decel_limit() -> None:
    rig = SimRig(exact_profile())
    c, dt, v = rig.profile.chassis, rig.mcu.dt, 0.5
    stop = watchdog_stop(rig, v, 0.0, smoothed=True)
    assert c.command_timeout < stop.fired <= c.command_timeout + dt + 1e-9
    a = c.linear_decel_limit
    assert a < rig.profile.motor.max_wheel_accel  # otherwise the motor limit would decide
    assert stop.duration == pytest.approx((v - c.min_speed) / a, abs=2 * dt)
    assert stop.distance == pytest.approx(v * v / (2 * a), abs=v * dt)
    assert rig.mcu.status & StatusBit.WATCHDOG_STOP  # and it holds, braked
    rig.run(0.5)
    assert rig.mcu.truth.v == 0.0 and rig.last("SystemStatus")["Braking"] == 1


@pytest.mark.parametrize("decel", [0.3, 2.0])
def test_smoothed_watchdog_stop_follows_the_configured_limit(decel: float) -> None:
    rig = SimRig(exact_profile(linear_decel_limit=decel))
    c, dt, v = rig.profile.chassis, rig.mcu.dt, 0.6
    stop = watchdog_stop(rig, v, 0.0, smoothed=True)
    assert stop.duration == pytest.approx((v - c.min_speed) / decel, abs=2 * dt)
    assert stop.distance == pytest.approx(v * v / (2 * decel), abs=v * dt)


def test_smoothed_watchdog_stop_decelerates_at_angular_decel_limit() -> None:
    rig = SimRig(exact_profile())
    c, dt, w = rig.profile.chassis, rig.mcu.dt, 1.0
    alpha = c.angular_decel_limit
    assert alpha * c.wheel_distant / 2 < rig.profile.motor.max_wheel_accel
    stop = watchdog_stop(rig, 0.0, w, smoothed=True)
    deadband = c.min_speed / (c.wheel_distant / 2)  # [rad/s] a rim speed below minSpeed
    assert stop.duration == pytest.approx((w - deadband) / alpha, abs=2 * dt)
    assert stop.turned == pytest.approx(w * w / (2 * alpha), abs=w * dt)
    assert stop.distance == pytest.approx(0.0, abs=1e-9)


def test_raw_watchdog_stop_brakes_at_the_motor_limit() -> None:
    rig = SimRig(exact_profile())
    c, dt, v = rig.profile.chassis, rig.mcu.dt, 0.5
    stop = watchdog_stop(rig, v, 0.0, smoothed=False)
    assert c.command_timeout < stop.fired <= c.command_timeout + dt + 1e-9
    a = rig.profile.motor.max_wheel_accel
    assert stop.duration == pytest.approx(v / a, abs=2 * dt)
    assert stop.distance == pytest.approx(v * v / (2 * a), abs=v * dt)


def test_estop_during_the_smoothed_ramp_brakes_at_the_motor_limit() -> None:
    rig = SimRig(exact_profile())
    c, dt, v = rig.profile.chassis, rig.mcu.dt, 0.5
    rig.enable()
    rig.drive(v, 0.0, 3.0, smoothed=True)
    while not rig.mcu.status & StatusBit.WATCHDOG_STOP:
        rig.step()
    rig.run(0.05)  # part of the way down the configured ramp
    left = rig.mcu.motors["left"]
    v1 = left.omega * left.geometry.radius
    assert v - c.linear_decel_limit * 0.07 < v1 < v - c.linear_decel_limit * 0.04
    rig.send("ControlCommand", Command="EStopSet")
    t0, x0 = rig.now, rig.mcu.truth.x
    while any(m.omega != 0.0 for m in rig.mcu.motors.values()):
        rig.step()
        assert rig.now - t0 < 1.0
    a = rig.profile.motor.max_wheel_accel
    assert rig.now - t0 == pytest.approx(v1 / a, abs=2 * dt)
    assert rig.mcu.truth.x - x0 == pytest.approx(v1 * v1 / (2 * a), abs=v1 * dt)


def test_a_command_during_the_smoothed_ramp_resumes_from_the_ramp() -> None:
    """No jump: the smoother carries on from the speed the ramp reached."""
    rig = SimRig(exact_profile())
    c, v = rig.profile.chassis, 0.5
    rig.enable()
    rig.drive(v, 0.0, 3.0, smoothed=True)
    while not rig.mcu.status & StatusBit.WATCHDOG_STOP:
        rig.step()
    rig.run(0.1)
    v1 = rig.mcu.smoother.v
    assert v1 == pytest.approx(v - c.linear_decel_limit * 0.105, abs=0.006)
    rig.drive(v, 0.0, 0.1, smoothed=True)  # commands again: accelerate from v1, not from 0
    assert not rig.mcu.status & StatusBit.WATCHDOG_STOP
    assert rig.mcu.smoother.v == pytest.approx(
        min(v, v1 + c.linear_accel_limit * 0.1), abs=0.006)
    assert math.isclose(rig.mcu.truth.v, rig.mcu.smoother.v, abs_tol=0.02)
