"""The ``[battery]`` table of the robot profile as validated, frozen dataclasses.

Defaults are a 16S LFP 40 Ah pack (51.2 V nominal) with the thresholds of
``physical-data.md`` section 2.4 (JBD/Libre Solar/LithiumHub figures, cited per field); an NMC
pack gets the Libre Solar NMC / foxBMS figures. Until the profile loader lands,
:func:`load_battery_config` reads any TOML file with a ``[battery]`` table; a key it does not
know is an error, a key it lacks keeps the chemistry default.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from lowerbase.bms.ocv import Chemistry
from lowerbase.errors import ConfigError
from lowerbase.files import read_toml


def _finite(name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{name} must be a finite number, got {value!r}")


@dataclass(frozen=True)
class ProtectionLimit:
    """One protection: trips when the value passes ``trip`` for ``trip_delay_s``, releases when
    it is back past ``release`` (the hysteresis) for ``release_delay_s``.

    Units are the measured quantity's: V for cell voltages, A for currents (magnitudes), degC.
    An *over* limit needs ``release < trip``; an *under* limit ``release > trip``.
    """

    trip: float
    release: float
    #: time the condition must hold before the switch opens [s]
    trip_delay_s: float = 2.0
    #: time the release condition must hold before the switch closes again [s]
    release_delay_s: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            _finite(f.name, getattr(self, f.name))
        if self.trip_delay_s < 0 or self.release_delay_s < 0:
            raise ConfigError("protection delays must be >= 0 s")

    def check(self, name: str, over: bool) -> None:
        """Raise :class:`ConfigError` unless the hysteresis points the right way."""
        if over and not self.release < self.trip:
            raise ConfigError(f"{name}: release {self.release} must be below trip {self.trip}")
        if not over and not self.release > self.trip:
            raise ConfigError(f"{name}: release {self.release} must be above trip {self.trip}")


#: protection name -> True for an over limit, False for an under limit
PROTECTION_DIRECTIONS: dict[str, bool] = {
    "cell_ov": True,
    "cell_uv": False,
    "charge_oc": True,
    "discharge_oc": True,
    "charge_ot": True,
    "charge_ut": False,
    "discharge_ot": True,
    "discharge_ut": False,
}


@dataclass(frozen=True)
class ProtectionConfig:
    """BMS thresholds. Cell voltages [V], currents [A] (magnitudes), temperatures [degC]."""

    cell_ov: ProtectionLimit
    cell_uv: ProtectionLimit
    charge_oc: ProtectionLimit
    discharge_oc: ProtectionLimit
    charge_ot: ProtectionLimit
    charge_ut: ProtectionLimit
    discharge_ot: ProtectionLimit
    discharge_ut: ProtectionLimit
    #: SOC below which the SOC_LOW warning bit is set [%]
    soc_low_percent: float = 15.0

    def __post_init__(self) -> None:
        for name, over in PROTECTION_DIRECTIONS.items():
            limit = getattr(self, name)
            if not isinstance(limit, ProtectionLimit):
                raise ConfigError(f"{name} must be a ProtectionLimit")
            limit.check(name, over)
        _finite("soc_low_percent", self.soc_low_percent)
        if not 0 <= self.soc_low_percent <= 100:
            raise ConfigError("soc_low_percent must be within 0-100 %")
        if self.cell_uv.release >= self.cell_ov.release:
            raise ConfigError("cell_uv.release must be below cell_ov.release")
        if self.charge_ut.trip >= self.charge_ot.trip:
            raise ConfigError("charge_ut.trip must be below charge_ot.trip")
        if self.discharge_ut.trip >= self.discharge_ot.trip:
            raise ConfigError("discharge_ut.trip must be below discharge_ot.trip")


def default_protection(chemistry: Chemistry, capacity_ah: float) -> ProtectionConfig:
    """Thresholds from ``physical-data.md`` 2.4 for ``chemistry``; currents scale with C."""
    c = capacity_ah
    # charge OC 1 C / 320 ms (Libre Solar); discharge OC 2 C / 1 s [D: AMR acceleration peaks];
    # both release after 32 s (JBD)
    charge_oc = ProtectionLimit(1.0 * c, 0.5 * c, 0.32, 32.0)
    discharge_oc = ProtectionLimit(2.0 * c, 1.0 * c, 1.0, 32.0)
    if chemistry is Chemistry.LFP:
        return ProtectionConfig(
            cell_ov=ProtectionLimit(3.65, 3.50, 2.0),  # JBD LFP
            cell_uv=ProtectionLimit(2.50, 2.75, 2.0),  # JBD LFP
            charge_oc=charge_oc,
            discharge_oc=discharge_oc,
            charge_ot=ProtectionLimit(45.0, 43.0, 2.0),  # Libre Solar, 2 K hysteresis
            charge_ut=ProtectionLimit(0.0, 5.0, 2.0),  # JBD
            discharge_ot=ProtectionLimit(65.0, 50.0, 2.0),  # LithiumHub Ionic
            discharge_ut=ProtectionLimit(-20.0, -10.0, 2.0),  # JBD
        )
    return ProtectionConfig(
        cell_ov=ProtectionLimit(4.25, 4.05, 2.0),  # Libre Solar NMC
        cell_uv=ProtectionLimit(3.00, 3.50, 2.0),  # Libre Solar NMC
        charge_oc=charge_oc,
        discharge_oc=discharge_oc,
        charge_ot=ProtectionLimit(45.0, 43.0, 2.0),  # Libre Solar / foxBMS MSL
        charge_ut=ProtectionLimit(0.0, 5.0, 2.0),
        discharge_ot=ProtectionLimit(60.0, 55.0, 2.0),  # foxBMS MSL / RSL
        discharge_ut=ProtectionLimit(-20.0, -15.0, 2.0),  # foxBMS MSL / RSL
    )


@dataclass(frozen=True)
class BatteryConfig:
    """A pack of ``cells_series`` cells in series (the ``[battery]`` profile table)."""

    chemistry: Chemistry = Chemistry.LFP
    cells_series: int = 16
    #: full-charge capacity today [Ah] (capacityFull; design x state of health)
    capacity_ah: float = 38.8
    #: design (nameplate) capacity [Ah] (capacityDesign); >= capacity_ah
    design_capacity_ah: float = 40.0
    #: pack DC resistance [ohm]: 16 x 1.2 mOhm cells + 10 mOhm bus bars, fuse, MOSFETs (2.2)
    internal_resistance_ohm: float = 0.0292
    #: heat capacity of the pack [J/K] (16 x ~0.85 kg prismatic cells x ~1100 J/(kg K))
    thermal_mass_j_per_k: float = 15000.0
    #: thermal resistance pack -> ambient [K/W] (time constant = this x thermal mass)
    thermal_resistance_k_per_w: float = 0.4
    #: ambient temperature [degC]
    ambient_temp_c: float = 25.0
    #: electronics draw at rest (upper computer, sensors, MCU) [A], on top of the motor load
    idle_current_a: float = 1.0
    #: SOC difference between the highest and the lowest cell [%] (sets the cell voltage spread)
    cell_soc_spread_percent: float = 1.0
    #: difference between the hottest and the coldest temperature sensor [degC]
    temp_sensor_spread_c: float = 1.0
    #: rated cycle life (batteryCycle)
    cycle_life: int = 3000
    #: charge cycles already done when the emulation starts (chargeCycle)
    charge_cycles: int = 0
    #: battery submodule number reported on the wire (0-15)
    submodule: int = 0
    #: charger constant current [A] (0.5 C)
    charge_current_a: float = 20.0
    #: charger constant voltage per cell [V] (LFP 3.60, NMC 4.20; 2.5)
    charge_voltage_per_cell_v: float = 3.60
    #: charge terminates when the CV current falls below this [A] (0.05 C)
    charge_termination_a: float = 2.0
    #: charge current limit below 15 degC [A] (0.2 C derating, 2.5)
    cold_charge_current_a: float = 8.0
    #: time constant of the average current that time-remaining uses [s]
    current_average_s: float = 60.0
    protection: ProtectionConfig = field(
        default_factory=lambda: default_protection(Chemistry.LFP, 38.8)
    )

    def __post_init__(self) -> None:
        if not isinstance(self.chemistry, Chemistry):
            raise ConfigError(f"chemistry must be a Chemistry, got {self.chemistry!r}")
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("chemistry", "protection"):
                continue
            if f.name in ("cells_series", "cycle_life", "charge_cycles", "submodule"):
                if isinstance(value, bool) or not isinstance(value, int):
                    raise ConfigError(f"battery.{f.name} must be an integer, got {value!r}")
            else:
                _finite(f"battery.{f.name}", value)
        positive = (
            "cells_series", "capacity_ah", "design_capacity_ah", "internal_resistance_ohm",
            "thermal_mass_j_per_k", "thermal_resistance_k_per_w", "cycle_life",
            "charge_current_a", "charge_voltage_per_cell_v", "charge_termination_a",
            "cold_charge_current_a", "current_average_s",
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise ConfigError(f"battery.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("idle_current_a", "cell_soc_spread_percent", "temp_sensor_spread_c",
                     "charge_cycles"):
            if getattr(self, name) < 0:
                raise ConfigError(f"battery.{name} must be >= 0, got {getattr(self, name)!r}")
        if self.cells_series > 32:
            raise ConfigError("battery.cells_series must be 1-32")
        if self.capacity_ah > self.design_capacity_ah:
            raise ConfigError("battery.capacity_ah (full) cannot exceed design_capacity_ah")
        if self.design_capacity_ah > 650:
            raise ConfigError("battery.design_capacity_ah must be <= 650 Ah (wire range)")
        if not 0 <= self.submodule <= 15:
            raise ConfigError("battery.submodule must be within 0-15")
        if self.charge_cycles > 65535 or self.cycle_life > 65535:
            raise ConfigError("battery cycle counts must fit 16 bits")
        if self.charge_termination_a >= self.charge_current_a:
            raise ConfigError("battery.charge_termination_a must be below charge_current_a")
        if not isinstance(self.protection, ProtectionConfig):
            raise ConfigError("battery.protection must be a ProtectionConfig")
        if self.charge_voltage_per_cell_v >= self.protection.cell_ov.trip:
            raise ConfigError("charge_voltage_per_cell_v must be below the cell OV trip")

    @property
    def nominal_voltage_v(self) -> float:
        """Nominal pack voltage [V] (3.2 V/cell LFP, 3.7 V/cell NMC)."""
        per_cell = 3.2 if self.chemistry is Chemistry.LFP else 3.7
        return per_cell * self.cells_series

    @property
    def cell_resistance_ohm(self) -> float:
        """Share of the pack resistance seen at one cell's sense wires [ohm]."""
        return self.internal_resistance_ohm / self.cells_series


def default_battery_config(chemistry: Chemistry | str = Chemistry.LFP) -> BatteryConfig:
    """The packaged defaults: 16S LFP 40 Ah (51.2 V) or 13S NMC 40 Ah (48.1 V)."""
    chem = _chemistry(chemistry)
    if chem is Chemistry.LFP:
        return BatteryConfig()
    return BatteryConfig(
        chemistry=chem,
        cells_series=13,
        # 13S10P 18650: 13 x 30 mOhm / 10 + 10 mOhm (2.2)
        internal_resistance_ohm=0.049,
        thermal_mass_j_per_k=12000.0,
        cycle_life=1000,
        charge_voltage_per_cell_v=4.20,
        charge_termination_a=0.8,  # 0.02 C
        protection=default_protection(chem, 38.8),
    )


def _chemistry(value: Any) -> Chemistry:
    if isinstance(value, Chemistry):
        return value
    try:
        return Chemistry(str(value).upper())
    except ValueError:
        raise ConfigError(f"battery.chemistry must be LFP or NMC, got {value!r}") from None


def _limit_from(name: str, base: ProtectionLimit, table: Any) -> ProtectionLimit:
    if not isinstance(table, Mapping):
        raise ConfigError(f"battery.protection.{name} must be a table")
    known = {f.name for f in fields(ProtectionLimit)}
    unknown = sorted(set(table) - known)
    if unknown:
        raise ConfigError(f"battery.protection.{name}: unknown keys {unknown}")
    return dataclasses.replace(base, **dict(table))


def battery_config_from_mapping(table: Mapping[str, Any]) -> BatteryConfig:
    """Build a :class:`BatteryConfig` from a ``[battery]`` table (a parsed TOML mapping).

    Missing keys keep the defaults of the table's ``chemistry``; protection currents that are
    not given scale with ``capacity_ah``.
    """
    data = dict(table)
    chem = _chemistry(data.pop("chemistry", "LFP"))
    base = default_battery_config(chem)
    protection_table = data.pop("protection", {})
    known = {f.name for f in fields(BatteryConfig)} - {"chemistry", "protection"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f"battery: unknown keys {unknown}")
    capacity = float(data.get("capacity_ah", base.capacity_ah))
    protection = default_protection(chem, capacity)
    if not isinstance(protection_table, Mapping):
        raise ConfigError("battery.protection must be a table")
    changes: dict[str, Any] = {}
    for key, value in protection_table.items():
        if key == "soc_low_percent":
            changes[key] = value
        elif key in PROTECTION_DIRECTIONS:
            changes[key] = _limit_from(key, getattr(protection, key), value)
        else:
            raise ConfigError(f"battery.protection: unknown key {key!r}")
    try:
        protection = dataclasses.replace(protection, **changes)
        return dataclasses.replace(base, chemistry=chem, protection=protection, **data)
    except TypeError as exc:  # a wrongly typed value that dataclasses cannot take
        raise ConfigError(f"battery: {exc}") from None


def load_battery_config(path: str | Path) -> BatteryConfig:
    """Read the ``[battery]`` table of a TOML profile file."""
    p = Path(path)
    doc = read_toml(p, "profile")
    table = doc.get("battery")
    if not isinstance(table, Mapping):
        raise ConfigError(f"{p}: no [battery] table")
    return battery_config_from_mapping(table)
