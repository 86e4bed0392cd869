"""Ground truth: where the emulated robot really is, given what its wheels really do.

The true wheel radii and track differ from the parameters by the profile's [truth] errors
(UMBmark E_d, E_b), and the ground speed of a wheel is ``(1 - s) * rim speed`` for a slip
fraction ``s`` (0 = rolling, 1 = spinning in place). Slip is episodic (physical-data.md 5.1):
:class:`SlipModel` produces it as events, never as white noise. Build the truth from the
profile as loaded: later parameter writes change what the firmware believes, not the robot.

What the robot can bump into is not the firmware model's business: whoever builds the loop may
install :class:`Surroundings` (``GroundTruth.surroundings``), which the integrator asks before
every move. A refused move leaves the robot where it was with ground speed 0;
``GroundTruth.blocked`` says so, and the MCU redoes the period's wheels as pressed against the
floor's traction (motor.py, "Pressed": held and stalling, or slipping with the friction's
current). Without surroundings nothing is asked and nothing changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from lowerbase.firmware_model.profile import ChassisParams, TruthParams

Vec3 = tuple[float, float, float]
TruePose = tuple[float, float, float]


class Surroundings(Protocol):
    """What the robot can collide with, seen from the ground-truth integrator."""

    def allowed(self, pose_from: TruePose, pose_to: TruePose, t: float) -> bool:
        """May the robot move from ``pose_from`` to ``pose_to`` (x, y, yaw in the truth frame
        [m, rad]) during the step ending at simulated time ``t`` [s]?"""
        ...


@dataclass(frozen=True)
class TrueGeometry:
    """The real robot: wheel radii [m] and track [m]."""

    radius_left: float
    radius_right: float
    track: float

    @classmethod
    def from_profile(cls, chassis: ChassisParams, truth: TruthParams) -> TrueGeometry:
        r = chassis.wheel_radius
        return cls(
            r * (1.0 + truth.left_radius_error),
            r * (1.0 + truth.right_radius_error),
            chassis.wheel_distant * (1.0 + truth.track_error),
        )


def integrate_pose(
    x: float, y: float, yaw: float, v: float, w: float, dt: float
) -> tuple[float, float, float]:
    """Exact pose after moving at constant v [m/s], w [rad/s] for dt [s] (arc, or line if w = 0).

    Uses the chord form (length 2 v/w sin(w dt/2) along yaw + w dt/2), which has no 0/0 at
    w -> 0: sin(h)/h falls back to its series below |h| = 1e-4.
    """
    h = 0.5 * w * dt
    sinc = 1.0 - h * h / 6.0 if abs(h) < 1e-4 else math.sin(h) / h
    chord = v * dt * sinc
    mid = yaw + h
    return x + chord * math.cos(mid), y + chord * math.sin(mid), yaw + 2.0 * h


class GroundTruth:
    """True pose x, y [m], yaw [rad, unwrapped], twist, acceleration and distance travelled."""

    def __init__(
        self, geometry: TrueGeometry, x: float = 0.0, y: float = 0.0, yaw: float = 0.0
    ) -> None:
        self.geometry = geometry
        self.x, self.y, self.yaw = x, y, yaw
        self.v = 0.0  # [m/s] true forward velocity of the base centre over the last step
        self.w = 0.0  # [rad/s] true yaw rate over the last step
        self.accel_x = 0.0  # [m/s^2] dv/dt over the last step
        self.distance = 0.0  # [m] sum of |ds| of the base centre
        self.surroundings: Surroundings | None = None  #: asked before each move (see module)
        self.blocked = False  #: the last step's move was refused by the surroundings
        self.blocked_steps = 0  #: steps refused so far

    def step(
        self, omega_left: float, omega_right: float, dt: float, slip: tuple[float, float] = (0, 0),
        t: float = math.nan,
    ) -> None:
        """Advance ``dt`` [s] with the TRUE mean wheel angular velocities [rad/s] over the step
        (angle turned / dt, for exact distances) and slip fractions (left, right); ``t`` [s] is
        the simulated time at the end of the step (what :class:`Surroundings` is asked at)."""
        if dt <= 0.0:
            return
        g = self.geometry
        v_left = (1.0 - slip[0]) * omega_left * g.radius_left
        v_right = (1.0 - slip[1]) * omega_right * g.radius_right
        v, w = 0.5 * (v_left + v_right), (v_right - v_left) / g.track
        pose = integrate_pose(self.x, self.y, self.yaw, v, w, dt)
        if self.surroundings is not None:
            self.blocked = not self.surroundings.allowed((self.x, self.y, self.yaw), pose, t)
            if self.blocked:  # pushing against something: the wheels slip, the base stays
                self.blocked_steps += 1
                pose, v, w = (self.x, self.y, self.yaw), 0.0, 0.0
        self.x, self.y, self.yaw = pose
        self.accel_x = (v - self.v) / dt
        self.v, self.w = v, w
        self.distance += abs(v) * dt

    @property
    def body_omega(self) -> Vec3:
        """Angular velocity of the base in its own frame [rad/s] (planar: only z)."""
        return 0.0, 0.0, self.w

    @property
    def body_accel(self) -> Vec3:
        """Acceleration of the base centre in its own frame [m/s^2], without gravity:
        tangential dv/dt on x, centripetal v*w on y."""
        return self.accel_x, self.v * self.w, 0.0


@dataclass(frozen=True)
class SlipEvent:
    """A wheel slipping by ``fraction`` from ``start`` [s] for ``duration`` [s]."""

    wheel: Literal["left", "right", "both"]
    start: float
    duration: float
    fraction: float

    def active(self, t: float) -> bool:
        """True while ``start <= t < start + duration`` [s]."""
        return self.start <= t < self.start + self.duration

    def fractions(self, t: float) -> tuple[float, float]:
        """Slip fractions (left, right) this event imposes at time ``t`` [s]."""
        if not self.active(t):
            return 0.0, 0.0
        return (
            self.fraction if self.wheel != "right" else 0.0,
            self.fraction if self.wheel != "left" else 0.0,
        )


class SlipModel:
    """Slip fractions per step: scheduled or injected events, random events per distance
    (``slip_rate_per_km``) and slip during hard acceleration (``accel_slip_threshold``)."""

    def __init__(self, params: TruthParams, rng: np.random.Generator | None = None) -> None:
        self.params = params
        self.rng = rng if rng is not None else np.random.default_rng(params.seed)
        self.events: list[SlipEvent] = []

    def add_event(self, event: SlipEvent) -> None:
        """Schedule an event (fault injection or a scenario)."""
        self.events.append(event)

    def step(
        self, t: float, distance: float, rim_accel: tuple[float, float] = (0.0, 0.0)
    ) -> tuple[float, float]:
        """Slip fractions (left, right) for the step starting at ``t`` [s], over which the base
        travels ``distance`` [m] with wheel rim accelerations ``rim_accel`` [m/s^2]."""
        p = self.params
        left = right = 0.0
        if self.events or p.slip_rate_per_km:
            left, right = self.event_fractions(t, distance)
        if p.accel_slip_threshold > 0.0:
            if abs(rim_accel[0]) > p.accel_slip_threshold:
                left = max(left, p.accel_slip_fraction)
            if abs(rim_accel[1]) > p.accel_slip_threshold:
                right = max(right, p.accel_slip_fraction)
        return left, right

    def event_fractions(self, t: float, distance: float) -> tuple[float, float]:
        """The first half of :meth:`step`: the random event drawn (or not), the events over
        dropped, and the slip fractions (left, right) of the events in force at ``t``; the
        compiled control period takes these as data and adds the acceleration slip itself."""
        p = self.params
        chance = p.slip_rate_per_km * abs(distance) / 1e3  # events per km * km
        if chance > 0.0 and self.rng.random() < chance:
            wheel: Literal["left", "right"] = "left" if self.rng.random() < 0.5 else "right"
            self.add_event(SlipEvent(wheel, t, p.slip_duration, p.slip_fraction))
        self.events = [e for e in self.events if t < e.start + e.duration]
        left = right = 0.0
        for e in self.events:
            s_l, s_r = e.fractions(t)
            left, right = max(left, s_l), max(right, s_r)
        return left, right
