"""The body controller: the seed's locomotion state machine over 12 actuators, standing up,
sitting down and trotting, base pose and velocity, and the fault reaction.

Requests (LocomotionRequest.Request = the wanted state) are checked against :data:`ALLOWED`
(docs/legged.md has it as a table). MOTOR_COMMUTATION, the end of standing up and the end of
sitting down are automatic: MOTOR_ENABLED requested from MOTOR_READY or MOTOR_DISABLED passes
through MOTOR_COMMUTATION (enter-motor-mode frames, ``commutation_time``); STANDING_MODE stands
up over ``stand_time`` (requests other than MOTOR_DISABLED meanwhile: Busy); SITDOWN_MODE sits
down over ``stand_time`` and then holds in MOTOR_ENABLED. A fault (an actuator error such as
over-temperature) is latched: standing or walking, the robot sits down and is then damped
(MOTOR_DISABLED); otherwise it is damped at once. While latched, only MOTOR_DISABLED,
COMM_DISABLED and MOTOR_READY are accepted; MOTOR_READY clears the latch once every actuator
reports error 0 after cooling (enter-motor-mode retried at the next commutation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lowerbase.legged import kernels
from lowerbase.legged.actuator import ActuatorBank, ActuatorParams
from lowerbase.legged.gait import (
    FRONT,
    SIDES,
    KinematicsError,
    LegGeometry,
    Trot,
    leg_fk,
    leg_ik,
    smoothstep,
)
from lowerbase.protocol.legged import (
    LEGS,
    NO_JOINT,
    NO_REQUEST,
    ActuatorError,
    Fault,
    LocomotionState,
    RequestResult,
    Special,
)

S = LocomotionState

#: state -> the states a request may ask for from it
ALLOWED: dict[LocomotionState, frozenset[LocomotionState]] = {
    S.COMM_DISABLED: frozenset({S.COMM_ENABLED}),
    S.COMM_ENABLED: frozenset({S.MOTOR_READY, S.COMM_DISABLED}),
    S.MOTOR_READY: frozenset({S.MOTOR_ENABLED, S.COMM_ENABLED, S.COMM_DISABLED}),
    S.MOTOR_COMMUTATION: frozenset({S.MOTOR_DISABLED}),
    S.MOTOR_ENABLED: frozenset({S.STANDING_MODE, S.IN_TEST_MODE, S.MOTOR_DISABLED}),
    S.IN_TEST_MODE: frozenset({S.MOTOR_ENABLED, S.MOTOR_DISABLED}),
    S.STANDING_MODE: frozenset({S.IN_CONTROL, S.SITDOWN_MODE, S.MOTOR_DISABLED}),
    S.IN_CONTROL: frozenset({S.STANDING_MODE, S.MOTOR_DISABLED}),
    S.SITDOWN_MODE: frozenset({S.MOTOR_DISABLED}),
    S.MOTOR_DISABLED: frozenset({S.MOTOR_ENABLED, S.MOTOR_READY, S.COMM_DISABLED}),
}
#: accepted while a fault is latched
WHILE_FAULTED = frozenset({S.MOTOR_DISABLED, S.COMM_DISABLED, S.MOTOR_READY})


@dataclass(frozen=True)
class BodyParams:
    mass: float  #: whole robot [kg]
    stand_height: float  #: base above ground standing [m]
    sit_height: float  #: base above ground sitting [m]
    stand_time: float  #: standing up or sitting down [s]
    commutation_time: float  #: [s]
    kp: float  #: joint stiffness of the body controller's commands [Nm/rad]
    kd: float  #: joint damping [Nm s/rad]
    damp_kd: float  #: damping of MOTOR_DISABLED's safe state is passive: kept for docs
    max_linear: float  #: [m/s]
    max_lateral: float  #: [m/s]
    max_yaw_rate: float  #: [rad/s]
    accel: float  #: body acceleration limit [m/s^2] (and rad/s^2)
    command_timeout: float  #: [s]
    gravity: float = 9.81


class Body:
    """The lower computer's body controller and its 12 actuators (simulated time)."""

    def __init__(self, params: BodyParams, geometry: LegGeometry,
                 actuators: tuple[ActuatorParams, ActuatorParams, ActuatorParams],
                 trot: Trot, ambient_c: float = 25.0) -> None:
        self.p, self.g, self.trot = params, geometry, trot
        self.bank = ActuatorBank([actuators[j] for _ in LEGS for j in range(3)], ambient_c)
        self.actuators = self.bank.actuators
        self.state = S.COMM_DISABLED
        self.last_request = NO_REQUEST
        self.result = RequestResult.NONE
        self.fault = Fault(0)
        self.fault_joint = NO_JOINT
        self.time = 0.0
        self._phase_start = 0.0  # start of the current timed transition
        self._gait_t = 0.0
        self.height = params.sit_height
        self._sit_from = params.sit_height
        self.x = self.y = self.yaw = 0.0
        self.v = [0.0, 0.0, 0.0]  # vx, vy (base frame), yaw rate: as walked
        self.vz = 0.0
        self.cmd = (0.0, 0.0, 0.0)
        self._cmd_time = -math.inf
        self.test_mode_commands = 0
        #: what kernels.legs reads and fills: the geometry, the trot, stance, a failing foot,
        #: the actuators' copper loss and electrical sum [W] of the last step
        self._geo = np.array([geometry.abad_link, geometry.thigh, geometry.calf,
                              geometry.hip_x, geometry.hip_y])
        self._trot = np.array([trot.period, trot.lift])
        self._stance = np.ones(4, np.bool_)  # of the last step: .stance
        self._bad = np.zeros(3)
        self.power = np.zeros(2)
        # the compiled kernel loaded (or compiled: once, seconds) now, not in the first period
        # of a real-time run: on a copy, so that nothing here changes
        self._legs(0.0, False, False, self.bank.copy())
        for leg in range(4):  # lying down: the sitting pose
            for j, q in enumerate(self._leg_angles(leg, (0.0, 0.0, -params.sit_height))):
                self.actuators[leg * 3 + j].position = q

    # -- requests ----------------------------------------------------------------------------

    def request(self, target: int) -> RequestResult:
        """A LocomotionRequest; returns (and reports) the result."""
        self.last_request = target if 0 <= target <= 9 else NO_REQUEST
        self.result = self._decide(target)
        return self.result

    def _decide(self, target: int) -> RequestResult:
        try:
            want = S(target)
        except ValueError:
            return RequestResult.NOT_ALLOWED
        if self.fault and want not in WHILE_FAULTED:
            return RequestResult.FAULTED
        busy = (self.state is S.STANDING_MODE and self._standing_up()) or \
            self.state in (S.SITDOWN_MODE, S.MOTOR_COMMUTATION)
        if busy and want is not S.MOTOR_DISABLED:
            return RequestResult.BUSY
        if want not in ALLOWED[self.state]:
            return RequestResult.NOT_ALLOWED
        if want is S.MOTOR_READY and self.fault:
            if any(a.error is not ActuatorError.NORMAL and a.temperature >= a.params.clear_c
                   for a in self.actuators):
                return RequestResult.FAULTED
            self.fault, self.fault_joint = Fault(0), NO_JOINT
            for a in self.actuators:
                a.error = ActuatorError.NORMAL
        self._enter(S.MOTOR_COMMUTATION if want is S.MOTOR_ENABLED and self.state in
                    (S.MOTOR_READY, S.MOTOR_DISABLED) else want)
        return RequestResult.ACCEPTED

    def _enter(self, state: LocomotionState) -> None:
        self.state = state
        self._phase_start = self.time
        if state is S.MOTOR_COMMUTATION:
            for a in self.actuators:
                a.special(Special.ENTER_MOTOR_MODE)
        elif state in (S.MOTOR_DISABLED, S.COMM_DISABLED, S.COMM_ENABLED, S.MOTOR_READY):
            for a in self.actuators:
                a.special(Special.EXIT_MOTOR_MODE)
        if state is S.IN_CONTROL:
            self._gait_t = 0.0
        if state is not S.IN_CONTROL:
            self.v = [0.0, 0.0, 0.0]

    def velocity_command(self, vx: float, vy: float, yaw_rate: float) -> None:
        p = self.p
        self.cmd = (min(max(vx, -p.max_linear), p.max_linear),
                    min(max(vy, -p.max_lateral), p.max_lateral),
                    min(max(yaw_rate, -p.max_yaw_rate), p.max_yaw_rate))
        self._cmd_time = self.time

    @property
    def command_fresh(self) -> bool:
        """Whether the last velocity command is younger than ``command_timeout``."""
        return self.time - self._cmd_time <= self.p.command_timeout

    def external_fault(self, fault: Fault) -> None:
        """Latch a fault the lower computer detects outside the actuators (body over-
        temperature, battery protection): the same reaction as an actuator fault (standing or
        walking: sit down, then damped; otherwise damped at once)."""
        if self.fault:
            self.fault |= fault
            return
        self.fault, self.fault_joint = fault, NO_JOINT
        if self.state in (S.STANDING_MODE, S.IN_CONTROL):
            self._sit_from = self.height
            self._enter(S.SITDOWN_MODE)
        elif self.state in (S.MOTOR_COMMUTATION, S.MOTOR_ENABLED, S.IN_TEST_MODE):
            self._enter(S.MOTOR_DISABLED)

    def _standing_up(self) -> bool:
        return self.height < self.p.stand_height - 1e-9

    # -- the control step --------------------------------------------------------------------

    def _leg_angles(self, leg: int, foot: tuple[float, float, float]) -> tuple[float, ...]:
        side = SIDES[leg]
        return leg_ik(foot[0], side * self.g.abad_link + foot[1], foot[2], side, self.g)

    def step(self, dt: float) -> None:
        """Advance by dt: state machine, joint targets, actuators, base."""
        self.time += dt
        self._check_faults()
        p = self.p
        held = self.state in (S.MOTOR_ENABLED, S.STANDING_MODE, S.IN_CONTROL, S.SITDOWN_MODE)
        prev_h = self.height
        if self.state is S.MOTOR_COMMUTATION and \
                self.time - self._phase_start >= p.commutation_time:
            self._enter(S.MOTOR_ENABLED)
        elif self.state is S.STANDING_MODE:
            u = smoothstep((self.time - self._phase_start) / p.stand_time)
            self.height = max(self.height, p.sit_height + (p.stand_height - p.sit_height) * u)
        elif self.state is S.SITDOWN_MODE:
            u = smoothstep((self.time - self._phase_start) / p.stand_time)
            start = self._sit_from
            self.height = start + (p.sit_height - start) * u
            if u >= 1.0:
                self._enter(S.MOTOR_DISABLED if self.fault else S.MOTOR_ENABLED)
        elif self.state is S.IN_CONTROL:
            self._walk(dt)
        self.vz = (self.height - prev_h) / dt
        if self.state is not S.SITDOWN_MODE:
            self._sit_from = self.height
        fail = self._legs(dt, self.state is S.IN_CONTROL, held, self.bank)
        if fail:
            x, y, z = self._bad
            what = "inside the ab/ad offset" if fail % 4 == kernels.INSIDE_OFFSET else \
                "out of the leg's reach"
            raise KinematicsError(f"{LEGS[fail // 4 - 1]} foot ({x:.3f}, {y:.3f}, {z:.3f}) "
                                  f"is {what}")

    @property
    def stance(self) -> list[bool]:
        """Which feet (FR, FL, RR, RL) were on the ground in the last step."""
        return [bool(st) for st in self._stance]

    def _legs(self, dt: float, walking: bool, held: bool, b: ActuatorBank) -> int:
        p = self.p
        vx, vy, wz = self.v
        return int(kernels.legs(dt, walking, held, self._gait_t, vx, vy, wz, self.height,
                                p.sit_height, p.mass * p.gravity, p.kp, p.kd, self._geo,
                                self._trot, self._stance, self._bad, b.position, b.velocity,
                                b.torque, b.temperature, b.zero_offset, b.motor_mode, b.error,
                                b.command, b.par, b.ambient, self.power))

    def _walk(self, dt: float) -> None:
        p = self.p
        cmd = self.cmd if self.time - self._cmd_time <= p.command_timeout else (0.0, 0.0, 0.0)
        step = p.accel * dt
        self.v = [v + min(max(c - v, -step), step) for v, c in zip(self.v, cmd, strict=True)]
        vx, vy, wz = self.v
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        self.x += (vx * c - vy * s) * dt
        self.y += (vx * s + vy * c) * dt
        self.yaw = math.atan2(math.sin(self.yaw + wz * dt), math.cos(self.yaw + wz * dt))
        self._gait_t += dt

    def _check_faults(self) -> None:
        if self.fault or not self.bank.error.any():
            return
        for i, a in enumerate(self.actuators):
            if a.error is not ActuatorError.NORMAL and not self.fault:
                self.fault = Fault.ACTUATOR_OVER_TEMPERATURE if \
                    a.error is ActuatorError.MOTOR_OVER_TEMPERATURE else Fault.ACTUATOR_ERROR
                self.fault_joint = i
                if self.state in (S.STANDING_MODE, S.IN_CONTROL):
                    self._sit_from = self.height
                    self._enter(S.SITDOWN_MODE)
                elif self.state in (S.MOTOR_COMMUTATION, S.MOTOR_ENABLED, S.IN_TEST_MODE):
                    self._enter(S.MOTOR_DISABLED)

    # -- what the lower computer reports -----------------------------------------------------

    def joint_positions(self) -> list[float]:
        return [a.reported_position for a in self.actuators]

    def quaternion(self) -> tuple[float, float, float, float]:
        """(x, y, z, w) of the base's yaw (the trot keeps the base level)."""
        return (0.0, 0.0, math.sin(self.yaw / 2), math.cos(self.yaw / 2))

    def foot_world(self, leg: int) -> tuple[float, float, float]:
        """Foot position on the ground (odometry frame) from the measured joint angles."""
        q = self.joint_positions()[leg * 3: leg * 3 + 3]
        fx, fy, fz = leg_fk((q[0], q[1], q[2]), SIDES[leg], self.g)
        bx, by = FRONT[leg] * self.g.hip_x + fx, SIDES[leg] * self.g.hip_y + fy
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return (self.x + bx * c - by * s, self.y + bx * s + by * c, self.height + fz)
