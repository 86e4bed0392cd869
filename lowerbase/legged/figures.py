"""Default figures of an MIT-mini-cheetah-class robot (sources in docs/legged.md): leg
geometry, gear ratios, motor constants and inertias from the MIT Cheetah-Software model
(MiniCheetah.h); thermal figures are this emulator's assumptions, stated there."""

from __future__ import annotations

from lowerbase.legged.actuator import ActuatorParams
from lowerbase.legged.body import Body, BodyParams
from lowerbase.legged.gait import LegGeometry, Trot

GEOMETRY = LegGeometry(abad_link=0.062, thigh=0.209, calf=0.195, hip_x=0.19, hip_y=0.049)


def actuator(gear_ratio: float, **changes: float) -> ActuatorParams:
    figures = dict(
        gear_ratio=gear_ratio, torque_max=3.0 * gear_ratio, kt=0.075, phase_resistance=0.173,
        rotor_inertia=63e-6, link_inertia=0.004, damping=0.01, thermal_resistance=2.0,
        thermal_time_constant=300.0, derate_c=80.0, fault_c=100.0, clear_c=70.0)
    figures.update(changes)
    return ActuatorParams(**figures)


BODY = BodyParams(mass=9.0, stand_height=0.28, sit_height=0.10, stand_time=1.0,
                  commutation_time=0.5, kp=80.0, kd=1.0, damp_kd=0.0, max_linear=1.5,
                  max_lateral=0.5, max_yaw_rate=2.0, accel=2.0, command_timeout=0.5)
TROT = Trot(period=0.4, lift=0.06)


def mini_cheetah(**actuator_changes: float) -> Body:
    """A Body with the default figures (actuator figures overridable for tests)."""
    acts = (actuator(6.0, **actuator_changes), actuator(6.0, **actuator_changes),
            actuator(9.33, **actuator_changes))
    return Body(BODY, GEOMETRY, acts, TROT)
