"""The body's temperature and the electrical load of the 12 actuators.

Body: one thermal mass C [J/K] through R [K/W] to ambient, heated by the electronics and a
share of the motors' copper loss:  C dT/dt = P - (T - T_amb) / R.  For a loss held constant
over a step the exact update is  T <- T_ss + (T - T_ss) exp(-dt / (R C)),  T_ss = T_amb + P R
(as the actuator windings; so T(t) = T_amb + P R (1 - exp(-t / RC)) from ambient, any dt).

Load: what the actuators draw from the pack, I = max(sum(tau w + copper loss), 0) / eta / V
(mechanical power on the joint side plus the winding loss, through the drivers' efficiency;
braking energy recovered by one actuator feeds the others, the pack is never charged). Both
sums are made with the actuators' step (:func:`lowerbase.legged.kernels.legs`, into
``Body.power``); :class:`~lowerbase.legged.lower.LeggedLower` applies eta and V.
"""

from __future__ import annotations

import math


class BodyThermal:
    """The body's temperature on the injected clock (``step(dt, power)``)."""

    def __init__(self, thermal_mass: float, thermal_resistance: float,
                 ambient_c: float) -> None:
        if thermal_mass <= 0 or thermal_resistance <= 0:
            raise ValueError("thermal mass and resistance must be > 0")
        self.r = thermal_resistance
        self.tau = thermal_mass * thermal_resistance
        self.ambient_c = ambient_c
        self.temperature = ambient_c

    def steady(self, power: float) -> float:
        """The temperature a constant ``power`` [W] settles at [degC]."""
        return self.ambient_c + power * self.r

    def step(self, dt: float, power: float) -> float:
        """Advance by ``dt`` [s] with ``power`` [W] held constant; the new temperature."""
        ss = self.steady(power)
        self.temperature = ss + (self.temperature - ss) * math.exp(-dt / self.tau)
        return self.temperature
