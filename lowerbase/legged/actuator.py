"""One MIT mini-cheetah actuator, joint side: the impedance law, rotor and link inertia,
winding heating and the firmware's motor mode, zero position and error code.

tau = kp (p_des - p) + kd (v_des - v) + tau_ff, saturated to the (derated) torque limit, as the
actuator firmware computes it at its own loop rate; the joint obeys
J dv/dt = tau + tau_ext - b v with J = rotor inertia * gear ratio^2 + link inertia (semi-implicit
Euler). The winding heats with the copper loss P = 3/2 R i_q^2 (i_q = tau / (Kt * gear ratio))
through a first-order thermal model, integrated exactly for a piecewise-constant loss:
T <- T_ss + (T - T_ss) exp(-dt / tau_th), T_ss = T_ambient + P R_th. Above ``derate_c`` the torque
limit falls linearly to half at ``fault_c``; at ``fault_c`` the actuator reports error 1 (motor
over-temperature) and leaves motor mode (zero torque) until it has cooled below ``clear_c`` and
receives an enter-motor-mode frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from lowerbase.protocol.legged import ActuatorError, Special


@dataclass(frozen=True)
class ActuatorParams:
    """Figures of one actuator (joint side); sources in docs/legged.md."""

    gear_ratio: float  #: motor turns per joint turn
    torque_max: float  #: joint torque limit [Nm]
    kt: float  #: motor torque constant [Nm/A] (q-axis current)
    phase_resistance: float  #: [ohm]
    rotor_inertia: float  #: about the spin axis [kg m^2]
    link_inertia: float  #: reflected load of the link alone [kg m^2]
    damping: float  #: viscous joint damping [Nm s/rad]
    thermal_resistance: float  #: winding to ambient [K/W]
    thermal_time_constant: float  #: [s]
    derate_c: float  #: torque derating starts [degC]
    fault_c: float  #: over-temperature fault [degC]
    clear_c: float  #: fault clears below [degC]

    @property
    def inertia(self) -> float:
        return self.rotor_inertia * self.gear_ratio ** 2 + self.link_inertia


def mit_torque(p: float, v: float, p_des: float, v_des: float, kp: float, kd: float,
               tau_ff: float, limit: float) -> float:
    """The MIT impedance law, saturated to +-limit."""
    tau = kp * (p_des - p) + kd * (v_des - v) + tau_ff
    return min(max(tau, -limit), limit)


class Actuator:
    """The actuator's state; :meth:`step` advances it by dt on the injected clock."""

    def __init__(self, params: ActuatorParams, ambient_c: float = 25.0,
                 position: float = 0.0) -> None:
        self.params = params
        self.ambient_c = ambient_c
        self.temperature = ambient_c
        self.position = position  #: joint angle [rad] (encoder, before the zero offset)
        self.velocity = 0.0
        self.torque = 0.0  #: torque applied in the last step [Nm]
        self.zero_offset = 0.0
        self.motor_mode = False
        self.error = ActuatorError.NORMAL
        self.command = (0.0, 0.0, 0.0, 0.0, 0.0)  #: p_des, v_des, kp, kd, tau_ff
        self._inertia = params.inertia

    # -- the protocol ---------------------------------------------------------------------

    def special(self, kind: Special) -> None:
        if kind is Special.ENTER_MOTOR_MODE:
            if self.error is ActuatorError.MOTOR_OVER_TEMPERATURE and \
                    self.temperature < self.params.clear_c:
                self.error = ActuatorError.NORMAL
            self.motor_mode = self.error is ActuatorError.NORMAL
            self.command = (self.reported_position, 0.0, 0.0, 0.0, 0.0)
        elif kind is Special.EXIT_MOTOR_MODE:
            self.motor_mode = False
        elif kind is Special.ZERO_POSITION:
            self.zero_offset = self.position

    def set_command(self, p_des: float, v_des: float, kp: float, kd: float,
                    tau_ff: float) -> None:
        """A command frame (ignored by the firmware outside motor mode)."""
        if self.motor_mode:
            self.command = (p_des, v_des, kp, kd, tau_ff)

    @property
    def reported_position(self) -> float:
        return self.position - self.zero_offset

    def torque_limit(self) -> float:
        """The torque limit after thermal derating."""
        p = self.params
        if self.temperature <= p.derate_c:
            return p.torque_max
        frac = (p.fault_c - self.temperature) / (p.fault_c - p.derate_c)
        return p.torque_max * (0.5 + 0.5 * min(max(frac, 0.0), 1.0))

    def current(self) -> float:
        """q-axis motor current of the applied torque [A]."""
        return self.torque / (self.params.kt * self.params.gear_ratio)

    # -- physics ----------------------------------------------------------------------------

    def step(self, dt: float, external_torque: float = 0.0) -> None:
        p = self.params
        if self.motor_mode:
            p_des, v_des, kp, kd, tau_ff = self.command
            self.torque = mit_torque(self.reported_position, self.velocity, p_des, v_des, kp,
                                     kd, tau_ff, self.torque_limit())
        else:
            self.torque = 0.0
        accel = (self.torque + external_torque - p.damping * self.velocity) / self._inertia
        self.velocity += accel * dt
        self.position += self.velocity * dt
        i_q = self.current()
        loss = 1.5 * p.phase_resistance * i_q * i_q
        steady = self.ambient_c + loss * p.thermal_resistance
        self.temperature = steady + (self.temperature - steady) * math.exp(
            -dt / p.thermal_time_constant)
        if self.temperature >= p.fault_c and self.error is ActuatorError.NORMAL:
            self.error = ActuatorError.MOTOR_OVER_TEMPERATURE
            self.motor_mode = False
