"""A robot driven into a wall loads its motors (issue 22 item 24; motor.py, "Pressed").

The world refuses the body's move; the wheels then meet the floor's traction
``F_t = mu * (m / 2) * g`` against the driver's saturated rim force
``F_m = I_stall * k_t * N * eta / r``. Two regimes, both closed form:

- held (``F_m <= F_t``): the wheels stop with the base, the motors draw ``stall_current``
  (+ idle), the stall bits rise ``stall_time`` after the first refused period (within one
  control period), the wheel odometry stays with the truth (no run through the wall);
- slipping (``F_m > F_t``, the default profile: 675 N against 441 N at mu 0.6): the wheels spin
  on at the setpoint but each motor carries the sliding friction, current
  ``F_t * r / (N * eta * k_t)`` + idle, and the pack current rises with it.

Simulated clock only; the world is tests/world/test_contact.py's room (a wall face at x = 6 m).
"""

from __future__ import annotations

import dataclasses
import math

import pytest

from lowerbase.firmware_model import lean_bits as bits
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import STANDARD_GRAVITY, Profile, load_profile
from lowerbase.simloop.loop import SimLoop
from lowerbase.world.truth import WorldSurroundings
from tests.world.test_contact import WALL_X, reach_x, ready, room

SPEED = 0.5  # [m/s] driven at the wall from 2.6 m before it
START_X = 3.0  # [m] map x of the start (the footprint's front is then 2.6 m from the wall)
TOUCH = 1e-4  # [m] the footprint may reach into the wall's cell by rounding (a zero-area touch)
LOADED_MASS = 250.0  # [kg] a 150 kg base with a 100 kg load: mu m g / 2 = 736 N > 675 N


@pytest.fixture(params=[True, False], ids=["lean", "hooked"])
def control_loop(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> bool:
    monkeypatch.setattr(Mcu, "lean", request.param)
    return bool(request.param)


def profile(mass: float | None = None) -> Profile:
    p = load_profile()
    return p if mass is None else dataclasses.replace(
        p, motor=dataclasses.replace(p.motor, robot_mass=mass))


def forces(p: Profile) -> tuple[float, float]:
    """(traction F_t, motor's saturated rim force F_m) [N] per wheel, from the profile."""
    m, c = p.motor, p.chassis
    radius = c.wheel_perimeter / (2.0 * math.pi)
    f_t = m.traction * 0.5 * m.robot_mass * STANDARD_GRAVITY
    f_m = m.stall_current * m.torque_constant * c.ratio_left * m.gear_efficiency / radius
    return f_t, f_m


class Run:
    """Drive at the wall for ``seconds`` and watch each period."""

    def __init__(self, p: Profile, seconds: float = 8.0) -> None:
        self.world = WorldSurroundings(room(), map_from_truth=(START_X, 5.0, 0.0))
        self.loop = SimLoop(p, surroundings=self.world)
        assert self.loop.run_until(ready, timeout=3.0)
        mcu = self.loop.mcu
        self.odometer0, self.distance0 = mcu.odometer, mcu.truth.distance
        self.first_blocked: float | None = None
        self.first_stall: float | None = None
        self.first_status: float | None = None  # any motor/encoder bit
        self.peak_current = 0.0  # [A] the larger |current| of the two motors
        self.blocked_current: list[float] = []  # [A] left motor, in refused periods
        self.loop.drive(SPEED, 0.0, seconds, on_step=self._watch)

    def _watch(self, loop: SimLoop) -> None:
        mcu = loop.mcu
        now = loop.now  # the end of the period just run
        if mcu.truth.blocked and self.first_blocked is None:
            self.first_blocked = now
        if mcu.truth.blocked:
            self.blocked_current.append(mcu.motors["left"].current)
        if mcu.status & (bits.L_STALL | bits.R_STALL) and self.first_stall is None:
            self.first_stall = now
        side = bits.SIDE_BITS[0] + bits.SIDE_BITS[1]
        if mcu.status & sum(side) and self.first_status is None:
            self.first_status = now
        self.peak_current = max(self.peak_current, *(abs(m.current) for m in mcu.motors.values()))

    @property
    def wheel_distance(self) -> float:
        """[m] what the encoders counted (the firmware's odometer)."""
        return self.loop.mcu.odometer - self.odometer0

    @property
    def true_distance(self) -> float:
        return self.loop.mcu.truth.distance - self.distance0


def test_the_profiles_put_the_robots_in_the_two_regimes() -> None:
    f_t, f_m = forces(profile())
    assert f_m > f_t  # default: 675 N > 441 N, the tyres slip
    f_t, f_m = forces(profile(LOADED_MASS))
    assert f_m <= f_t  # loaded: 675 N <= 736 N, the floor holds the wheels


def test_a_held_robot_stalls_at_the_wall(control_loop: bool) -> None:
    p = profile(LOADED_MASS)
    run = Run(p)
    mcu, truth = run.loop.mcu, run.loop.mcu.truth
    dt = mcu.dt
    # the true pose stops at the wall
    assert WALL_X - 1.1 * SPEED * dt <= reach_x(START_X + truth.x, truth.yaw) <= WALL_X + TOUCH
    assert run.first_blocked is not None
    # the wheels stopped with the base: the encoders count the truth's distance, not more
    assert run.wheel_distance == pytest.approx(run.true_distance, abs=0.02)
    # the driver saturated: stall current (+ idle) in each refused period while commanded
    stall = p.motor.stall_current + p.motor.idle_current
    assert max(run.blocked_current) == pytest.approx(stall, rel=1e-12)
    assert sum(i == max(run.blocked_current) for i in run.blocked_current) \
        >= round(p.motor.stall_time / dt)
    # the stall bits stall_time after the first refused period, within one control period;
    # no other motor or encoder bit before them
    assert run.first_stall is not None and run.first_status == run.first_stall
    assert abs(run.first_stall - (run.first_blocked + p.motor.stall_time)) <= dt + 1e-9
    assert mcu.status & bits.L_STALL and mcu.status & bits.R_STALL
    assert mcu.motion_fault and mcu.state.name == "FAULT"
    assert not mcu.status & (bits.L_ENC | bits.R_ENC)  # a held wheel is no encoder fault
    # the driver's odometry did not run through the wall
    assert run.loop.driver.ekf.pose[0] == pytest.approx(truth.x, abs=0.02)


def test_a_slipping_robot_loads_its_motors_with_the_traction(control_loop: bool) -> None:
    p = profile()
    run = Run(p, seconds=7.0)
    mcu, truth = run.loop.mcu, run.loop.mcu.truth
    assert WALL_X - 1.1 * SPEED * mcu.dt <= reach_x(START_X + truth.x, truth.yaw) <= WALL_X + TOUCH
    assert truth.blocked
    m, c = p.motor, p.chassis
    f_t, _ = forces(p)
    pack = 2 * m.idle_current
    for motor in mcu.motors.values():  # each at its true radius (the profile's [truth])
        g = motor.geometry
        sliding = f_t * g.radius / (g.ratio * m.gear_efficiency * m.torque_constant)
        # pressed and spinning at the setpoint: the motor carries the tyre's sliding friction
        assert motor.current == pytest.approx(sliding + m.idle_current, rel=1e-12)
        pack += motor.current * abs(motor.motor_rpm) / c.max_rpm
    # under the over-current limit (16.6 A < 20 A) and turning: no fault bit
    assert sliding + m.idle_current < m.over_current_limit
    assert run.first_status is None
    # the wheels really turn while slipping: the encoders count past the truth
    assert run.wheel_distance > run.true_distance + 0.3
    # the pack: idle + each motor's current times its speed share (Mcu.load_current)
    assert mcu.load_current() == pytest.approx(pack, rel=1e-12)
    assert mcu.load_current() > 4.0  # [A] on free floor at 0.5 m/s: 2 * 0.3 + 2 * 0.8 * 0.32
