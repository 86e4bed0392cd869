"""The legged profile: the shipped legged.toml sets every key to the dataclass default, bad
values are one-line ConfigErrors naming file and key, unknown keys and sections are refused,
[battery] is validated at load and defaults to the legged pack."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest

from lowerbase.bms.ocv import Chemistry
from lowerbase.errors import ConfigError
from lowerbase.files import read_toml
from lowerbase.firmware_model.profile import field_defaults
from lowerbase.legged import figures
from lowerbase.legged.profile import (
    LEGGED_BATTERY,
    SECTIONS,
    LeggedProfile,
    legged_profile_from_dict,
    legged_profile_path,
    load_legged_profile,
    merged_battery,
)


def test_shipped_file_equals_the_defaults() -> None:
    data = read_toml(legged_profile_path(), "profile")
    for name, cls in SECTIONS.items():
        assert data[name] == field_defaults(cls), name  # every key set, each the default
    assert merged_battery(data["battery"]) == merged_battery({})
    assert set(data["battery"]) == set(LEGGED_BATTERY)
    assert load_legged_profile() == LeggedProfile()


def test_every_key_has_a_comment() -> None:
    lines = legged_profile_path().read_text(encoding="utf-8").splitlines()
    for cls in SECTIONS.values():
        for f in fields(cls):  # type: ignore[arg-type]
            line = next(x for x in lines if x.split("=")[0].strip() == f.name)
            assert "#" in line, line


def test_battery_is_the_legged_pack() -> None:
    b = LeggedProfile().battery
    assert b.chemistry is Chemistry.NMC and b.cells_series == 6
    assert b.capacity_ah == 6.0 and b.protection.discharge_oc.trip == 60.0
    # a key given replaces one default; the other protection limits keep theirs
    p = legged_profile_from_dict({"battery": {"capacity_ah": 5.0,
                                              "protection": {"cell_uv": {"trip": 3.1}}}})
    assert p.battery.capacity_ah == 5.0 and p.battery.cells_series == 6
    assert p.battery.protection.cell_uv.trip == 3.1
    assert p.battery.protection.discharge_oc.trip == 60.0


def test_figures_are_the_profile_defaults() -> None:
    p = LeggedProfile()
    body = figures.mini_cheetah()
    assert body.p == p.body_params() and body.g == p.geometry() and body.trot == p.trot()
    made = p.make_body()
    assert [a.params for a in body.actuators] == [a.params for a in made.actuators]
    assert made.actuators[2].params.torque_max == pytest.approx(3.0 * 9.33)


@pytest.mark.parametrize(("data", "words"), [
    ({"body": {"mass": -1}}, ["body.mass = -1", "1..200 kg"]),
    ({"body": {"mass": "heavy"}}, ["body.mass = 'heavy'", "not a number"]),
    ({"body": {"mas": 9}}, ["unknown key body.mas", "did you mean body.mass"]),
    ({"legs": {}}, ["unknown section legs", "did you mean leg"]),
    ({"body": []}, ["[body] must be a table"]),
    ({"body": {"sit_height": 0.3}}, ["body.sit_height = 0.3", "below body.stand_height"]),
    ({"body": {"stand_height": 0.5}}, ["body.stand_height = 0.5", "out of the leg's reach"]),
    ({"actuator": {"motor_torque_max": 4.0}}, ["motor_torque_max", "18 Nm"]),
    ({"actuator": {"clear_c": 120.0}}, ["below fault_c"]),
    ({"thermal": {"body_clear_c": 80.0}}, ["body_clear_c < body_fault_c"]),
    ({"power": {"critical_battery_soc": 30.0}}, ["power.critical_battery_soc = 30"]),
    ({"battery": {"cells_series": 0}}, ["battery.cells_series must be > 0"]),
    ({"battery": {"colour": "red"}}, ["battery: unknown keys ['colour']"]),
    ({"battery": 3}, ["[battery] must be a table"]),
])
def test_bad_values_are_one_line_errors(data: dict[str, object], words: list[str]) -> None:
    with pytest.raises(ConfigError) as info:
        legged_profile_from_dict(data, source="robot.toml")
    text = str(info.value)
    assert text.startswith("robot.toml: ") and "\n" not in text
    for w in words:
        assert w in text


def test_a_copied_file_loads_with_its_changes(tmp_path: Path) -> None:
    text = legged_profile_path().read_text(encoding="utf-8")
    path = tmp_path / "dog.toml"
    path.write_text(text.replace("mass = 9.0", "mass = 12.0"), encoding="utf-8")
    p = load_legged_profile(path)
    assert p.body.mass == 12.0 and p.source == str(path)
    assert p.make_body().p.mass == 12.0
