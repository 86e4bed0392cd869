"""The legged robot's profile: validated, frozen dataclasses loaded from a TOML file.

Same rules as the wheeled profile (:mod:`lowerbase.firmware_model.profile`): every numeric
field declares its unit and allowed range next to its default, a bad value is a one-line
:class:`~lowerbase.errors.ConfigError` naming the file, ``section.key``, the value and what is
allowed; missing keys take the defaults below, which equal ``lowerbase/profiles/legged.toml``
(a test checks it); unknown keys and sections are refused. ``[battery]`` is validated at load
by :func:`lowerbase.bms.config.battery_config_from_mapping`.

Figures of an MIT-mini-cheetah-class robot; the source of each is in legged.toml's comments
and docs/legged.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

from lowerbase.bms.config import BatteryConfig, battery_config_from_mapping
from lowerbase.errors import ConfigError
from lowerbase.files import read_toml
from lowerbase.firmware_model.profile import _fmt, _num, _Validated, build_sections
from lowerbase.legged.actuator import ActuatorParams
from lowerbase.legged.body import Body, BodyParams
from lowerbase.legged.gait import LegGeometry, Trot
from lowerbase.protocol.legged import JOINTS, MOTOR_IDS, T_MAX

#: the legged pack's [battery] defaults (a Go1-class 6S Li-ion pack; sources in legged.toml);
#: a profile's [battery] keys replace these one by one (protection limits one by one too)
LEGGED_BATTERY: Mapping[str, Any] = MappingProxyType({
    "chemistry": "NMC", "cells_series": 6, "capacity_ah": 6.0, "design_capacity_ah": 6.0,
    "internal_resistance_ohm": 0.1, "thermal_mass_j_per_k": 600.0,
    "thermal_resistance_k_per_w": 3.0, "idle_current_a": 1.0, "cycle_life": 500,
    "charge_current_a": 3.0, "charge_voltage_per_cell_v": 4.2, "charge_termination_a": 0.12,
    "cold_charge_current_a": 1.2,
    "protection": MappingProxyType({"discharge_oc": MappingProxyType(
        {"trip": 60.0, "release": 30.0, "trip_delay_s": 1.0, "release_delay_s": 32.0})}),
})


def merged_battery(table: Mapping[str, Any]) -> dict[str, Any]:
    """``table`` over :data:`LEGGED_BATTERY` (protection limits merged one by one)."""
    out: dict[str, Any] = {**LEGGED_BATTERY, **table}
    given = table.get("protection", {})
    if isinstance(given, Mapping):
        out["protection"] = {**LEGGED_BATTERY["protection"], **given}
    return out


@dataclass(frozen=True)
class BodySection(_Validated):
    """The body controller (limits within BodyVelocityCommand's wire ranges)."""

    SECTION: ClassVar[str] = "body"
    mass: float = _num(9.0, 1.0, 200.0, "kg")
    stand_height: float = _num(0.28, 0.02, 2.0, "m")
    sit_height: float = _num(0.10, 0.01, 2.0, "m")
    stand_time: float = _num(1.0, 0.05, 30.0, "s")
    commutation_time: float = _num(0.5, 0.0, 10.0, "s")
    kp: float = _num(80.0, 0.0, 500.0, "Nm/rad")
    kd: float = _num(1.0, 0.0, 5.0, "Nm*s/rad")
    max_linear: float = _num(1.5, 0.01, 3.0, "m/s")
    max_lateral: float = _num(0.5, 0.0, 3.0, "m/s")
    max_yaw_rate: float = _num(2.0, 0.01, 6.0, "rad/s")
    accel: float = _num(2.0, 0.01, 50.0, "m/s^2")
    command_timeout: float = _num(0.5, 0.02, 10.0, "s")

    def _check_relations(self) -> None:
        if self.sit_height >= self.stand_height:
            raise ConfigError(f"body.sit_height = {_fmt(self.sit_height)} must be below "
                              f"body.stand_height = {_fmt(self.stand_height)} m")


@dataclass(frozen=True)
class LegSection(_Validated):
    SECTION: ClassVar[str] = "leg"
    abad_link: float = _num(0.062, 0.0, 1.0, "m")
    thigh: float = _num(0.209, 0.01, 2.0, "m")
    calf: float = _num(0.195, 0.01, 2.0, "m")
    hip_x: float = _num(0.19, 0.0, 2.0, "m")
    hip_y: float = _num(0.049, 0.0, 2.0, "m")


@dataclass(frozen=True)
class GaitSection(_Validated):
    SECTION: ClassVar[str] = "gait"
    period: float = _num(0.4, 0.05, 5.0, "s")
    lift: float = _num(0.06, 0.0, 0.5, "m")


@dataclass(frozen=True)
class ActuatorSection(_Validated):
    """The 12 actuators (one motor type; the gear ratio per joint)."""

    SECTION: ClassVar[str] = "actuator"
    hip_gear_ratio: float = _num(6.0, 1.0, 100.0)
    thigh_gear_ratio: float = _num(6.0, 1.0, 100.0)
    calf_gear_ratio: float = _num(9.33, 1.0, 100.0)
    motor_torque_max: float = _num(3.0, 0.01, 100.0, "Nm")
    kt: float = _num(0.075, 0.001, 10.0, "Nm/A")
    phase_resistance: float = _num(0.173, 0.001, 100.0, "ohm")
    rotor_inertia: float = _num(63e-6, 1e-8, 1.0, "kg*m^2")
    link_inertia: float = _num(0.004, 0.0, 10.0, "kg*m^2")
    damping: float = _num(0.01, 0.0, 10.0, "Nm*s/rad")
    thermal_resistance: float = _num(2.0, 0.01, 100.0, "K/W")
    thermal_time_constant: float = _num(300.0, 0.1, 100_000.0, "s")
    derate_c: float = _num(80.0, -40.0, 200.0, "degC")
    fault_c: float = _num(100.0, -40.0, 200.0, "degC")
    clear_c: float = _num(70.0, -40.0, 200.0, "degC")

    def _check_relations(self) -> None:
        if not self.clear_c < self.fault_c or not self.derate_c < self.fault_c:
            raise ConfigError("actuator: clear_c and derate_c must be below fault_c "
                              f"(got {_fmt(self.clear_c)}, {_fmt(self.derate_c)}, "
                              f"{_fmt(self.fault_c)} degC)")
        for joint in JOINTS:
            limit = T_MAX[MOTOR_IDS[joint]]
            joint_max = self.motor_torque_max * getattr(self, f"{joint}_gear_ratio")
            if joint_max > limit + 1e-9:
                raise ConfigError(
                    f"actuator.motor_torque_max x actuator.{joint}_gear_ratio = "
                    f"{joint_max:g} Nm exceeds the {joint} command's torque range {limit:g} Nm "
                    "(legged.dbc)")

    def params(self, joint: str) -> ActuatorParams:
        """The actuator figures of ``joint`` (hip, thigh or calf)."""
        ratio = getattr(self, f"{joint}_gear_ratio")
        return ActuatorParams(
            gear_ratio=ratio, torque_max=self.motor_torque_max * ratio, kt=self.kt,
            phase_resistance=self.phase_resistance, rotor_inertia=self.rotor_inertia,
            link_inertia=self.link_inertia, damping=self.damping,
            thermal_resistance=self.thermal_resistance,
            thermal_time_constant=self.thermal_time_constant, derate_c=self.derate_c,
            fault_c=self.fault_c, clear_c=self.clear_c)


@dataclass(frozen=True)
class ThermalSection(_Validated):
    """The body's temperature (lowerbase.legged.thermal) and the ambient of everything."""

    SECTION: ClassVar[str] = "thermal"
    ambient_c: float = _num(25.0, -40.0, 60.0, "degC")
    body_thermal_mass: float = _num(3000.0, 1.0, 1e6, "J/K")
    body_thermal_resistance: float = _num(0.8, 0.001, 100.0, "K/W")
    motor_heat_fraction: float = _num(0.5, 0.0, 1.0)
    body_fault_c: float = _num(70.0, -40.0, 200.0, "degC")
    body_clear_c: float = _num(60.0, -40.0, 200.0, "degC")

    def _check_relations(self) -> None:
        if not self.ambient_c < self.body_clear_c < self.body_fault_c:
            raise ConfigError(
                f"thermal: ambient_c < body_clear_c < body_fault_c is required (got "
                f"{_fmt(self.ambient_c)}, {_fmt(self.body_clear_c)}, "
                f"{_fmt(self.body_fault_c)} degC)")


@dataclass(frozen=True)
class PowerSection(_Validated):
    """The lower computer's own reading of the BMS (as the wheeled [power])."""

    SECTION: ClassVar[str] = "power"
    low_battery_soc: float = _num(20.0, 0.0, 100.0, "%")
    critical_battery_soc: float = _num(5.0, 0.0, 100.0, "%")
    battery_temp_warning: float = _num(50.0, -40.0, 120.0, "degC")
    drive_efficiency: float = _num(0.9, 0.1, 1.0)

    def _check_relations(self) -> None:
        if self.critical_battery_soc > self.low_battery_soc:
            raise ConfigError(
                f"power.critical_battery_soc = {_fmt(self.critical_battery_soc)} must not be "
                f"above power.low_battery_soc = {_fmt(self.low_battery_soc)} %")


SECTIONS: Mapping[str, type[_Validated]] = MappingProxyType({
    "body": BodySection, "leg": LegSection, "gait": GaitSection, "actuator": ActuatorSection,
    "thermal": ThermalSection, "power": PowerSection,
})


@dataclass(frozen=True)
class LeggedProfile:
    """One legged robot; ``battery_table`` is the raw [battery] table, ``battery`` its
    validated :class:`~lowerbase.bms.config.BatteryConfig`."""

    body: BodySection = field(default_factory=BodySection)
    leg: LegSection = field(default_factory=LegSection)
    gait: GaitSection = field(default_factory=GaitSection)
    actuator: ActuatorSection = field(default_factory=ActuatorSection)
    thermal: ThermalSection = field(default_factory=ThermalSection)
    power: PowerSection = field(default_factory=PowerSection)
    battery_table: Mapping[str, Any] = field(default_factory=dict, hash=False, compare=False)
    source: str = field(default="<defaults>", compare=False)

    def __post_init__(self) -> None:
        reach = self.leg.thigh + self.leg.calf
        if self.body.stand_height >= reach:
            raise ConfigError(f"body.stand_height = {_fmt(self.body.stand_height)} m is out of "
                              f"the leg's reach (leg.thigh + leg.calf = {reach:g} m)")
        if self.body.sit_height <= abs(self.leg.thigh - self.leg.calf):
            raise ConfigError(f"body.sit_height = {_fmt(self.body.sit_height)} m is below the "
                              "folded leg (|leg.thigh - leg.calf|)")
        object.__setattr__(self, "battery",
                           battery_config_from_mapping(merged_battery(self.battery_table)))

    battery: BatteryConfig = field(init=False, hash=False)

    def body_params(self) -> BodyParams:
        b = self.body
        return BodyParams(
            mass=b.mass, stand_height=b.stand_height, sit_height=b.sit_height,
            stand_time=b.stand_time, commutation_time=b.commutation_time, kp=b.kp, kd=b.kd,
            damp_kd=0.0, max_linear=b.max_linear, max_lateral=b.max_lateral,
            max_yaw_rate=b.max_yaw_rate, accel=b.accel, command_timeout=b.command_timeout)

    def geometry(self) -> LegGeometry:
        g = self.leg
        return LegGeometry(abad_link=g.abad_link, thigh=g.thigh, calf=g.calf, hip_x=g.hip_x,
                           hip_y=g.hip_y)

    def trot(self) -> Trot:
        return Trot(period=self.gait.period, lift=self.gait.lift)

    def make_body(self) -> Body:
        """The body controller with this profile's figures."""
        acts = (self.actuator.params("hip"), self.actuator.params("thigh"),
                self.actuator.params("calf"))
        return Body(self.body_params(), self.geometry(), acts, self.trot(),
                    ambient_c=self.thermal.ambient_c)


def legged_profile_path() -> Path:
    """Path of the packaged legged profile (lowerbase/profiles/legged.toml)."""
    return Path(str(resources.files("lowerbase") / "profiles" / "legged.toml"))


def load_legged_profile(path: str | Path | None = None) -> LeggedProfile:
    """Load and validate a legged profile TOML file (None = the packaged one)."""
    p = Path(path) if path is not None else legged_profile_path()
    return legged_profile_from_dict(read_toml(p, "profile"), source=str(p))


def legged_profile_from_dict(data: Mapping[str, Any], source: str = "<dict>") -> LeggedProfile:
    """A LeggedProfile from parsed TOML; ConfigError messages start with ``source``."""
    try:
        sections, battery = build_sections(data, SECTIONS)
        return LeggedProfile(**sections, battery_table=battery, source=source)
    except ConfigError as e:
        raise ConfigError(f"{source}: {e}") from None
