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

The state of a body's 12 actuators lives in one :class:`ActuatorBank` (arrays, stepped by the
compiled :func:`lowerbase.legged.kernels.actuator_step`); an :class:`Actuator` is one of them,
read and written by name.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lowerbase.legged import kernels as k
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


#: the MIT impedance law, saturated to +-limit (compiled: the actuators' step applies it)
mit_torque = k.mit_torque


def _par_row(p: ActuatorParams) -> list[float]:
    row = [0.0] * k.N_PAR
    row[k.INERTIA], row[k.DAMPING], row[k.RESISTANCE] = p.inertia, p.damping, p.phase_resistance
    row[k.KT_GEAR], row[k.R_THERMAL] = p.kt * p.gear_ratio, p.thermal_resistance
    row[k.TAU_THERMAL], row[k.TORQUE_MAX] = p.thermal_time_constant, p.torque_max
    row[k.DERATE_C], row[k.FAULT_C], row[k.CLEAR_C] = p.derate_c, p.fault_c, p.clear_c
    return row


class ActuatorBank:
    """The state of ``len(params)`` actuators as arrays (one element per actuator):
    ``position`` [rad] (encoder, before the zero offset), ``velocity`` [rad/s], ``torque``
    applied in the last step [Nm], winding ``temperature`` [degC], ``zero_offset`` [rad],
    ``motor_mode``, ``error`` (ActuatorError values), ``command`` (p_des, v_des, kp, kd,
    tau_ff per row); ``par`` holds the figures the kernels use (kernels.INERTIA ...)."""

    def __init__(self, params: Sequence[ActuatorParams], ambient_c: float = 25.0,
                 positions: Sequence[float] | None = None) -> None:
        n = len(params)
        self.params = list(params)
        self.ambient = np.full(n, float(ambient_c))
        self.position = np.zeros(n) if positions is None else np.array(positions, np.float64)
        self.velocity = np.zeros(n)
        self.torque = np.zeros(n)
        self.temperature = np.full(n, float(ambient_c))
        self.zero_offset = np.zeros(n)
        self.motor_mode = np.zeros(n, np.bool_)
        self.error = np.zeros(n, np.int64)
        self.command = np.zeros((n, 5))
        self.par = np.array([_par_row(p) for p in params], np.float64).reshape(n, k.N_PAR)
        self.actuators = [Actuator.of(self, i) for i in range(n)]

    def copy(self) -> ActuatorBank:
        """An independent bank in this one's state."""
        other = ActuatorBank(self.params)
        for name in ("ambient", "position", "velocity", "torque", "temperature", "zero_offset",
                     "motor_mode", "error", "command", "par"):
            setattr(other, name, getattr(self, name).copy())
        return other

    def set_params(self, i: int, params: ActuatorParams) -> None:
        self.params[i] = params
        self.par[i] = _par_row(params)

    def step(self, i: int, dt: float, external_torque: float = 0.0) -> None:
        """Actuator ``i`` by ``dt`` [s] (the bodies step all of them in kernels.legs)."""
        k.actuator_step(i, float(dt), float(external_torque), self.position, self.velocity,
                        self.torque, self.temperature, self.zero_offset, self.motor_mode,
                        self.error, self.command, self.par, self.ambient)


class Actuator:
    """One actuator: ``Actuator(params)`` alone, or ``bank.actuators[i]``; :meth:`step`
    advances it by dt on the injected clock."""

    __slots__ = ("bank", "i")

    def __init__(self, params: ActuatorParams, ambient_c: float = 25.0,
                 position: float = 0.0) -> None:
        self.bank = ActuatorBank([params], ambient_c, [position])
        self.i = 0

    @classmethod
    def of(cls, bank: ActuatorBank, i: int) -> Actuator:
        """Actuator ``i`` of ``bank``."""
        a = cls.__new__(cls)
        a.bank, a.i = bank, i
        return a

    @property
    def params(self) -> ActuatorParams:
        return self.bank.params[self.i]

    @params.setter
    def params(self, value: ActuatorParams) -> None:
        self.bank.set_params(self.i, value)

    @property
    def ambient_c(self) -> float:
        return float(self.bank.ambient[self.i])

    @property
    def position(self) -> float:
        """Joint angle [rad] (encoder, before the zero offset)."""
        return float(self.bank.position[self.i])

    @position.setter
    def position(self, value: float) -> None:
        self.bank.position[self.i] = value

    @property
    def velocity(self) -> float:
        return float(self.bank.velocity[self.i])

    @velocity.setter
    def velocity(self, value: float) -> None:
        self.bank.velocity[self.i] = value

    @property
    def torque(self) -> float:
        """Torque applied in the last step [Nm]."""
        return float(self.bank.torque[self.i])

    @property
    def temperature(self) -> float:
        return float(self.bank.temperature[self.i])

    @temperature.setter
    def temperature(self, value: float) -> None:
        self.bank.temperature[self.i] = value

    @property
    def zero_offset(self) -> float:
        return float(self.bank.zero_offset[self.i])

    @property
    def motor_mode(self) -> bool:
        return bool(self.bank.motor_mode[self.i])

    @property
    def error(self) -> ActuatorError:
        return ActuatorError(int(self.bank.error[self.i]))

    @error.setter
    def error(self, value: ActuatorError) -> None:
        self.bank.error[self.i] = int(value)

    @property
    def command(self) -> tuple[float, float, float, float, float]:
        """p_des, v_des, kp, kd, tau_ff."""
        p, v, kp, kd, tau = (float(x) for x in self.bank.command[self.i])
        return p, v, kp, kd, tau

    # -- the protocol ---------------------------------------------------------------------

    def special(self, kind: Special) -> None:
        b, i = self.bank, self.i
        if kind is Special.ENTER_MOTOR_MODE:
            if self.error is ActuatorError.MOTOR_OVER_TEMPERATURE and \
                    self.temperature < self.params.clear_c:
                b.error[i] = ActuatorError.NORMAL
            b.motor_mode[i] = b.error[i] == ActuatorError.NORMAL
            b.command[i] = (self.reported_position, 0.0, 0.0, 0.0, 0.0)
        elif kind is Special.EXIT_MOTOR_MODE:
            b.motor_mode[i] = False
        elif kind is Special.ZERO_POSITION:
            b.zero_offset[i] = b.position[i]

    def set_command(self, p_des: float, v_des: float, kp: float, kd: float,
                    tau_ff: float) -> None:
        """A command frame (ignored by the firmware outside motor mode)."""
        if self.motor_mode:
            self.bank.command[self.i] = (p_des, v_des, kp, kd, tau_ff)

    @property
    def reported_position(self) -> float:
        return float(self.bank.position[self.i] - self.bank.zero_offset[self.i])

    def torque_limit(self) -> float:
        """The torque limit after thermal derating."""
        return float(k.torque_limit(self.temperature, self.bank.par[self.i]))

    def current(self) -> float:
        """q-axis motor current of the applied torque [A]."""
        return self.torque / (self.params.kt * self.params.gear_ratio)

    # -- physics ----------------------------------------------------------------------------

    def step(self, dt: float, external_torque: float = 0.0) -> None:
        self.bank.step(self.i, dt, external_torque)
