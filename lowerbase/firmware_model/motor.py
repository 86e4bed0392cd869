"""One wheel's motor and servo driver: accel ramp, velocity-loop lag, current, stall, over-current.

Model (continuous time, solved exactly per step so results do not depend on the step size):
the driver's setpoint ``r`` ramps toward the target at most ``max_wheel_accel`` (at the rim),
and the wheel speed follows ``r`` through a first-order lag ``time_constant``:
``dw/dt = (r - w) / tau``. Targets below ``min_speed`` (rim) are a deadband: the wheel stays
put. The current estimate covers inertia (half the robot mass per wheel), rolling resistance,
viscous friction and an external load, through the gear ratio and efficiency, plus an idle
current. Faults: an injected block (the wheel does not turn; a commanded motor draws
``stall_current``), stall detection, over-current (modelled or injected) which latches and
makes the driver brake to zero until :meth:`WheelMotor.clear_faults`.

Pressed against the world (:attr:`WheelMotor.pressed`, set by the MCU for a period whose body
move the world refused: a wall, a rack, a person): the base stands, so the tyre meets the
floor's traction ``F_t = mu * (robot_mass / 2) * g`` [N] at the rim (``mu`` = MotorParams.traction).
The driver's velocity loop saturates at ``stall_current``, i.e. a rim force
``F_m = stall_current * torque_constant * ratio * gear_efficiency / radius`` [N]. If
``F_m <= F_t`` the floor holds the wheel (:attr:`WheelMotor.held`): it does not turn, the motor
draws ``stall_current`` while commanded, and stall (and over-current) detection follow as for an
injected block. Otherwise the tyre slips: the wheel turns as the velocity loop drives it and the
motor carries the sliding friction ``F_t`` (kinetic taken equal to static), whose current is
``F_t * radius / (ratio * gear_efficiency * torque_constant)`` plus the idle current.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from lowerbase.firmware_model.kinematics import Side, motor_rpm_to_wheel_rad_s
from lowerbase.firmware_model.profile import STANDARD_GRAVITY, ChassisParams, MotorParams

#: what :meth:`WheelMotor.save` keeps: omega, setpoint, current, over_current, stalled, the two
#: fault timers and the steady-step cache
MotorState = tuple[float, float, float, bool, bool, float, float, "float | None", float, float]

STATUS_OVER_CURRENT = 0x1  # WheelFeedback.Left/RightDriverStatus bit 0
STATUS_STALLED = 0x2  # bit 1 (bit 2, encoder fault, belongs to the encoder)


@dataclass(frozen=True)
class WheelGeometry:
    """What the firmware believes about one wheel: nominal radius [m], gear ratio (motor:wheel),
    rim deadband ``min_speed`` [m/s] and motor limit ``max_rpm`` [rpm]."""

    radius: float
    ratio: float
    min_speed: float
    max_rpm: float

    @classmethod
    def from_chassis(cls, chassis: ChassisParams, side: Side) -> WheelGeometry:
        ratio = chassis.ratio_left if side == "left" else chassis.ratio_right
        return cls(chassis.wheel_radius, ratio, chassis.min_speed, chassis.max_rpm)


def follow(omega0: float, r0: float, slope: float, t: float, tau: float) -> tuple[float, float]:
    """Exact first-order lag ``tau`` [s] from speed ``omega0`` following the ramp
    ``r(s) = r0 + slope*s`` for ``t`` [s]; returns (speed at t, angle travelled [rad])."""
    if tau <= 0.0:
        return r0 + slope * t, r0 * t + 0.5 * slope * t * t
    c = omega0 - r0 + slope * tau
    one_minus_e = -math.expm1(-t / tau)
    omega = r0 + slope * t - slope * tau + c * (1.0 - one_minus_e)
    angle = r0 * t + 0.5 * slope * t * t - slope * tau * t + c * tau * one_minus_e
    return omega, angle


class WheelMotor:
    """State: wheel speed ``omega`` [rad/s], driver setpoint [rad/s], current [A], fault flags."""

    def __init__(self, params: MotorParams, geometry: WheelGeometry) -> None:
        self.params = params  # replaceable at any time; the state is kept
        self.geometry = geometry  # replaceable (parameter writes); the state is kept
        self.omega = 0.0  # [rad/s] wheel angular velocity, forward positive
        self.setpoint = 0.0  # [rad/s] the driver's ramped setpoint
        self.current = 0.0  # [A] phase current, sign of the torque
        self.blocked = False  # injected: the wheel cannot turn
        self.pressed = False  # the world refused the body's move: the tyre meets the traction
        self.over_current = False  # latched until clear_faults()
        self.stalled = False  # latched until clear_faults()
        self._over_time = 0.0  # [s] how long |current| has exceeded the limit
        self._stall_time = 0.0  # [s] how long the wheel has lagged far behind its setpoint
        self._key: tuple[MotorParams, WheelGeometry, float] | None = None  # see _constants
        #: the fixed point of the last step (steady speed): its target (None: none), its
        #: speed (within rounding of the target) and angle; see _steady_step
        self._steady: float | None = None
        self._steady_omega = self._steady_angle = 0.0

    @property
    def rim_speed(self) -> float:
        """Rim speed [m/s] at the nominal radius."""
        return self.omega * self.geometry.radius

    @property
    def motor_rpm(self) -> float:
        """Motor speed [rpm] = omega * ratio * 60 / 2pi."""
        return self.omega * self.geometry.ratio * 60.0 / (2.0 * math.pi)

    @property
    def traction_force(self) -> float:
        """[N] the most the floor holds at the rim: mu * (robot_mass / 2) * g."""
        p = self.params
        return p.traction * 0.5 * p.robot_mass * STANDARD_GRAVITY

    @property
    def stall_force(self) -> float:
        """[N] the rim force of the motor at ``stall_current`` (the driver's saturation)."""
        p, g = self.params, self.geometry
        return p.stall_current * p.torque_constant * g.ratio * p.gear_efficiency / g.radius

    @property
    def held(self) -> bool:
        """Pressed, does the floor hold the wheel (the motor cannot overcome the traction)?"""
        return self.stall_force <= self.traction_force

    def save(self) -> MotorState:
        """The state a step changes, for :meth:`restore` (a period redone as pressed)."""
        return (self.omega, self.setpoint, self.current, self.over_current, self.stalled,
                self._over_time, self._stall_time, self._steady, self._steady_omega,
                self._steady_angle)

    def restore(self, state: MotorState) -> None:
        """Back to a state from :meth:`save`."""
        (self.omega, self.setpoint, self.current, self.over_current, self.stalled,
         self._over_time, self._stall_time, self._steady, self._steady_omega,
         self._steady_angle) = state

    def press(self, state: MotorState, target: float, dt: float, *, brake: bool) -> float:
        """Redo the step made from ``state`` as pressed against the world (module docstring):
        the angle [rad] the wheel really turned."""
        self.restore(state)
        self.pressed = True
        try:
            return self.step(target, dt, brake=brake)
        finally:
            self.pressed = False

    @property
    def status_bits(self) -> int:
        """DriverStatus bits 0 (over-current) and 1 (stalled)."""
        return (STATUS_OVER_CURRENT if self.over_current else 0) | (
            STATUS_STALLED if self.stalled else 0
        )

    def inject_over_current(self) -> None:
        """Latch an over-current fault now (the driver then brakes to zero)."""
        self.over_current = True

    def clear_faults(self) -> None:
        """Clear the latched over-current and stall flags (FaultClear)."""
        self.over_current = self.stalled = False
        self._over_time = self._stall_time = 0.0

    def step(
        self, target: float, dt: float, *, brake: bool = False, load_force: float = 0.0
    ) -> float:
        """Advance ``dt`` [s] toward ``target`` wheel speed [rad/s]; return the angle turned [rad].

        ``brake`` (or a latched over-current) ramps to zero instead. ``load_force`` [N] is an
        external force at the rim opposing forward motion (e.g. a slope); it only affects the
        current. The mean speed over the step is the returned angle / dt.

        This is the control loop's hottest function: :func:`follow` (twice), the current and
        the fault timers are written out inline, with the same operations in the same order,
        and :meth:`_constants` caches what depends only on the parameters and ``dt``.
        """
        if dt <= 0.0:
            return 0.0
        p, g = self.params, self.geometry
        if (p, g, dt) != self._key:
            self._constants(dt)
        if brake or self.over_current or abs(target) * g.radius < g.min_speed:
            target = 0.0
        limit = self._limit
        target = min(max(target, -limit), limit)
        omega0 = self.omega
        steady = (target == self._steady and omega0 == self._steady_omega
                  and self.setpoint == target and not self.blocked and load_force == 0.0
                  and not self.pressed)
        if steady:  # the last step's input state and target, which it left unchanged
            return self._steady_step(dt, target)
        setpoint0 = self.setpoint
        alpha = self._alpha  # [rad/s^2]; 0 = no ramp
        tau = p.time_constant
        r0 = target if alpha == 0.0 else self.setpoint
        t_ramp = 0.0 if alpha == 0.0 else min(dt, abs(target - r0) / alpha)
        slope = math.copysign(alpha, target - r0) if t_ramp > 0.0 else 0.0
        # follow(omega0, r0, slope, t_ramp, tau)
        t = t_ramp
        if tau <= 0.0:
            omega, angle = r0 + slope * t, r0 * t + 0.5 * slope * t * t
        else:
            c = omega0 - r0 + slope * tau
            one_minus_e = -math.expm1(-t / tau) if t else self._ome_zero
            omega = r0 + slope * t - slope * tau + c * (1.0 - one_minus_e)
            angle = r0 * t + 0.5 * slope * t * t - slope * tau * t + c * tau * one_minus_e
        self.setpoint = setpoint = target if t_ramp < dt or alpha == 0.0 else r0 + slope * t_ramp
        # follow(omega, setpoint, 0.0, dt - t_ramp, tau)
        t = dt - t_ramp
        if tau <= 0.0:
            omega, angle2 = setpoint + 0.0 * t, setpoint * t + 0.5 * 0.0 * t * t
        else:
            c = omega - setpoint + 0.0 * tau
            one_minus_e = self._ome_dt if t == dt else -math.expm1(-t / tau)
            omega = setpoint + 0.0 * t - 0.0 * tau + c * (1.0 - one_minus_e)
            angle2 = setpoint * t + 0.5 * 0.0 * t * t - 0.0 * tau * t + c * tau * one_minus_e
        angle += angle2
        if self.blocked or (self.pressed and self.held):
            omega, angle = 0.0, 0.0
        self.omega = omega
        if self.blocked or self.pressed:
            self._update_current((omega - omega0) / dt, load_force)
        else:  # _update_current, unblocked
            wheel_accel = (omega - omega0) / dt
            radius = g.radius
            v = omega * radius
            sign_v = 0.0 if v == 0.0 else math.copysign(1.0, v)
            force = self._half_mass * wheel_accel * radius  # [N] at the rim
            force += sign_v * self._rolling + p.viscous_friction * v
            force += load_force
            wheel_torque = force * radius
            eta = p.gear_efficiency
            if wheel_torque * omega >= 0.0:  # motoring
                motor_torque = wheel_torque / (g.ratio * eta)
            else:
                motor_torque = wheel_torque * eta / g.ratio
            amps = motor_torque / p.torque_constant
            self.current = amps + math.copysign(p.idle_current, amps)
        # _update_faults
        over = abs(self.current) > p.over_current_limit
        self._over_time = self._over_time + dt if over else 0.0
        if over and self._over_time >= p.over_current_time:
            self.over_current = True
        lagging = abs(setpoint) * g.radius >= p.stall_speed and abs(omega) < 0.5 * abs(setpoint)
        self._stall_time = self._stall_time + dt if lagging else 0.0
        if lagging and self._stall_time >= p.stall_time:
            self.stalled = True
        self._steady = None
        if (omega == omega0 and setpoint == target and setpoint0 == target and target != 0.0
                and omega0 != 0.0 and not self.blocked and load_force == 0.0
                and not self.pressed):
            self._steady, self._steady_omega, self._steady_angle = target, omega0, angle
        return angle

    def _steady_step(self, dt: float, target: float) -> float:
        """:meth:`step` from the state and target of the last step, which left the state as it
        found it (a fixed point of the lag to the last bit: the setpoint at the target, the
        speed unchanged; not blocked, no load force, neither target nor speed zero, so no
        sign of zero to tell apart): the same arithmetic on the same floats gives the same
        angle, speed, setpoint and current again; only the fault timers move."""
        self._update_faults(dt)
        return self._steady_angle

    def _constants(self, dt: float) -> None:
        """What :meth:`step` needs of the parameters, geometry and ``dt``, computed as the
        uncached expressions compute it (the same floats)."""
        p, g = self.params, self.geometry
        self._key = (p, g, dt)
        self._steady = None
        self._limit = motor_rpm_to_wheel_rad_s(g.max_rpm, g.ratio)
        self._alpha = p.max_wheel_accel / g.radius
        tau = p.time_constant
        self._ome_zero = -math.expm1(-0.0 / tau) if tau > 0.0 else 0.0
        self._ome_dt = -math.expm1(-dt / tau) if tau > 0.0 else 0.0
        self._half_mass = 0.5 * p.robot_mass
        self._rolling = p.rolling_resistance * self._half_mass * STANDARD_GRAVITY

    def _update_current(self, wheel_accel: float, load_force: float) -> None:
        p, g = self.params, self.geometry
        commanded = abs(self.setpoint) * g.radius >= p.stall_speed and not self.over_current
        if self.blocked or (self.pressed and self.held):
            self.current = math.copysign(p.stall_current, self.setpoint) if commanded else 0.0
            self.current += math.copysign(p.idle_current, self.current)
            return
        if self.pressed:  # slipping: the motor carries the tyre's sliding friction
            force = 0.0 if self.omega == 0.0 else math.copysign(self.traction_force, self.omega)
            amps = force * g.radius / (g.ratio * p.gear_efficiency * p.torque_constant)
            self.current = amps + math.copysign(p.idle_current, amps)
            return
        m = 0.5 * p.robot_mass
        v = self.omega * g.radius
        sign_v = 0.0 if v == 0.0 else math.copysign(1.0, v)
        force = m * wheel_accel * g.radius  # [N] at the rim
        force += sign_v * p.rolling_resistance * m * STANDARD_GRAVITY + p.viscous_friction * v
        force += load_force
        wheel_torque = force * g.radius
        motoring = wheel_torque * self.omega >= 0.0
        eta = p.gear_efficiency
        motor_torque = wheel_torque / (g.ratio * eta) if motoring else wheel_torque * eta / g.ratio
        amps = motor_torque / p.torque_constant
        self.current = amps + math.copysign(p.idle_current, amps)

    def _update_faults(self, dt: float) -> None:
        p, g = self.params, self.geometry
        over = abs(self.current) > p.over_current_limit
        self._over_time = self._over_time + dt if over else 0.0
        if over and self._over_time >= p.over_current_time:
            self.over_current = True
        lagging = abs(self.setpoint) * g.radius >= p.stall_speed and abs(self.omega) < 0.5 * abs(
            self.setpoint
        )
        self._stall_time = self._stall_time + dt if lagging else 0.0
        if lagging and self._stall_time >= p.stall_time:
            self.stalled = True
