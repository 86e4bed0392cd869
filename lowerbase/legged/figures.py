"""Default figures of an MIT-mini-cheetah-class robot, as objects: the defaults of
:mod:`lowerbase.legged.profile` (which equal ``lowerbase/profiles/legged.toml``, where each
figure's source is given). Kept for tests and benches that build a :class:`Body` directly."""

from __future__ import annotations

from dataclasses import replace

from lowerbase.legged.actuator import ActuatorParams
from lowerbase.legged.body import Body
from lowerbase.legged.profile import LeggedProfile

DEFAULTS = LeggedProfile()
GEOMETRY = DEFAULTS.geometry()
BODY = DEFAULTS.body_params()
TROT = DEFAULTS.trot()


def actuator(gear_ratio: float, **changes: float) -> ActuatorParams:
    """The default actuator with ``gear_ratio`` (torque limit = motor limit x ratio)."""
    base = replace(DEFAULTS.actuator.params("hip"), gear_ratio=gear_ratio,
                   torque_max=DEFAULTS.actuator.motor_torque_max * gear_ratio)
    return replace(base, **changes)


def mini_cheetah(**actuator_changes: float) -> Body:
    """A Body with the default figures (actuator figures overridable for tests)."""
    a = DEFAULTS.actuator
    acts = (actuator(a.hip_gear_ratio, **actuator_changes),
            actuator(a.thigh_gear_ratio, **actuator_changes),
            actuator(a.calf_gear_ratio, **actuator_changes))
    return Body(BODY, GEOMETRY, acts, TROT, ambient_c=DEFAULTS.thermal.ambient_c)
