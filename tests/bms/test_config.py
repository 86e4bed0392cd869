"""The [battery] profile table: defaults, validation and TOML loading."""

from __future__ import annotations

from pathlib import Path

import pytest

from lowerbase.bms.config import (
    BatteryConfig,
    ProtectionLimit,
    battery_config_from_mapping,
    default_battery_config,
    load_battery_config,
)
from lowerbase.bms.ocv import Chemistry
from lowerbase.errors import ConfigError, LowerbaseError


def test_defaults_are_a_16s_lfp_40ah_pack() -> None:
    cfg = default_battery_config()
    assert cfg.chemistry is Chemistry.LFP and cfg.cells_series == 16
    assert cfg.design_capacity_ah == 40.0 and cfg.nominal_voltage_v == pytest.approx(51.2)
    assert cfg.protection.cell_ov == ProtectionLimit(3.65, 3.50, 2.0)
    assert cfg.protection.cell_uv == ProtectionLimit(2.50, 2.75, 2.0)
    assert cfg.design_capacity_ah >= cfg.capacity_ah


@pytest.mark.parametrize(
    "changes",
    [
        {"cells_series": 0},
        {"capacity_ah": 50.0},  # above design
        {"internal_resistance_ohm": -1.0},
        {"capacity_ah": float("nan")},
        {"submodule": 16},
        {"cells_series": 2.5},
        {"charge_voltage_per_cell_v": 3.7},  # above the OV trip
    ],
)
def test_invalid_values_raise_config_error(changes: dict[str, object]) -> None:
    with pytest.raises(ConfigError):
        BatteryConfig(**changes)  # type: ignore[arg-type]


def test_hysteresis_must_point_the_right_way() -> None:
    with pytest.raises(ConfigError, match="release"):
        battery_config_from_mapping({"protection": {"cell_ov": {"release": 3.70}}})
    with pytest.raises(ConfigError, match="release"):
        battery_config_from_mapping({"protection": {"cell_uv": {"release": 2.40}}})


def test_toml_profile(tmp_path: Path) -> None:
    path = tmp_path / "robot.toml"
    path.write_text(
        "[chassis]\nname = 'x'\n\n[battery]\nchemistry = 'NMC'\ncapacity_ah = 30.0\n"
        "design_capacity_ah = 32.0\n\n[battery.protection.cell_uv]\ntrip = 3.1\n",
        encoding="utf-8",
    )
    cfg = load_battery_config(path)
    assert cfg.chemistry is Chemistry.NMC and cfg.cells_series == 13
    assert cfg.capacity_ah == 30.0
    assert cfg.protection.cell_uv.trip == 3.1 and cfg.protection.cell_uv.release == 3.5
    assert cfg.protection.charge_oc.trip == pytest.approx(30.0)  # 1 C of the given capacity


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[battery]\nvoltage = 48\n", "unknown keys"),
        ("[battery]\nchemistry = 'LCO'\n", "LFP or NMC"),
        ("[chassis]\n", "no \\[battery\\]"),
        ("[battery\n", "invalid TOML"),
        ("[battery.protection]\nfoo = 1\n", "unknown key"),
    ],
)
def test_bad_profiles(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=match):
        load_battery_config(path)


def test_missing_file_is_a_lowerbase_error(tmp_path: Path) -> None:
    with pytest.raises(LowerbaseError, match="cannot read"):
        load_battery_config(tmp_path / "nope.toml")
