"""Profile loading and validation: defaults, wire names, one-line ConfigErrors."""

from __future__ import annotations

import re
from dataclasses import fields, replace
from pathlib import Path

import cantools
import pytest

from lowerbase.errors import ConfigError
from lowerbase.firmware_model.profile import (
    CHASSIS_WIRE_NAMES,
    SECTIONS,
    ChassisParams,
    ImuParams,
    Profile,
    default_profile_path,
    field_defaults,
    load_profile,
    profile_from_dict,
)
from lowerbase.protocol.codec import DBC_PATH


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "robot.toml"
    path.write_text(text, encoding="utf-8")
    return path


def config_error(tmp_path: Path, text: str) -> str:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_profile(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    return message


def test_default_profile_equals_dataclass_defaults() -> None:
    profile = load_profile()
    assert profile == Profile()
    assert profile.source == str(default_profile_path())
    assert profile.battery == {}
    assert profile.chassis.wheel_perimeter == 0.6283
    assert profile.chassis.pulse_per_circle == 10000
    assert isinstance(profile.chassis.pulse_per_circle, int)


def test_default_toml_sets_and_comments_every_field() -> None:
    text = default_profile_path().read_text(encoding="utf-8")
    for section, cls in SECTIONS.items():
        assert f"[{section}]" in text
        for name in field_defaults(cls):
            lines = [ln for ln in text.splitlines() if re.match(rf"{name}\s*=", ln)]
            assert lines, f"{section}.{name} missing from default.toml"
            assert all("#" in ln for ln in lines), f"{section}.{name} has no comment"


def test_wire_names_are_the_dbc_parameter_index_table() -> None:
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, cantools.database.can.Database)
    for message in ("ParameterRequest", "ParameterResponse"):
        choices = db.get_message_by_name(message).get_signal_by_name("Index").choices
        assert choices is not None
        names = [str(choices[i]) for i in sorted(choices)]
        assert names == list(CHASSIS_WIRE_NAMES)
    assert set(CHASSIS_WIRE_NAMES.values()) == {f.name for f in fields(ChassisParams)}


def test_wire_dict_round_trip_and_single_writes() -> None:
    chassis = ChassisParams()
    wire = chassis.as_wire_dict()
    assert wire["wheelPerimeter"] == 0.6283 and wire["maxRPM"] == 3000.0
    assert ChassisParams.from_wire_dict(wire) == chassis
    written = chassis.with_wire_value("maxLinear", 0.8)
    assert written.max_linear == 0.8 and chassis.max_linear == 1.2
    assert chassis.with_wire_value("pulsePerCircle", 2500.0).pulse_per_circle == 2500
    with pytest.raises(ConfigError, match=r"pulse_per_circle = 2500\.5 is not an integer"):
        chassis.with_wire_value("pulsePerCircle", 2500.5)
    with pytest.raises(ConfigError, match=r"max_linear = 5 is out of range; .*0\.01\.\.3 m/s"):
        chassis.with_wire_value("maxLinear", 5.0)
    with pytest.raises(ConfigError, match="out of range"):
        chassis.with_wire_value("wheelDistant", float("nan"))
    with pytest.raises(ConfigError, match="unknown chassis parameter 'maxLin'"):
        chassis.with_wire_value("maxLin", 1.0)


def test_partial_profile_takes_defaults_and_keeps_battery_opaque(tmp_path: Path) -> None:
    path = write(
        tmp_path, "[chassis]\nmax_linear = 0.9\n[battery]\nchemistry = 'LFP'\ncells = 16\n"
    )
    profile = load_profile(path)
    assert profile.chassis == replace(ChassisParams(), max_linear=0.9)
    assert profile.imu == ImuParams()
    assert profile.battery == {"chemistry": "LFP", "cells": 16}


def test_replace_revalidates() -> None:
    profile = Profile()
    changed = profile.replace(chassis=replace(profile.chassis, max_angular=0.5))
    assert changed.chassis.max_angular == 0.5
    with pytest.raises(ConfigError, match=r"chassis\.max_angular = -1"):
        replace(profile.chassis, max_angular=-1.0)


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        (
            "[chassis]\nwheel_perimter = 0.6\n",
            r"unknown key chassis\.wheel_perimter; did you mean "
            r"chassis\.wheel_perimeter\?",
        ),
        ("[chasis]\n", r"unknown section chasis; did you mean chassis\?"),
        ("chassis = 3\n", r"\[chassis\] must be a table"),
        (
            "[chassis]\nmax_linear = 5.0\n",
            r"chassis\.max_linear = 5 is out of range; "
            r"allowed: a number in 0\.01\.\.3 m/s",
        ),
        ("[chassis]\nwheel_distant = nan\n", r"chassis\.wheel_distant = nan is out of range"),
        ("[imu]\nrate_hz = inf\n", r"imu\.rate_hz = inf is out of range"),
        (
            "[chassis]\nmax_rpm = '3000'\n",
            r"chassis\.max_rpm = '3000' is not a number; allowed: "
            r"a number in 1\.\.100000 rpm",
        ),
        (
            "[chassis]\npulse_per_circle = 10000.5\n",
            r"chassis\.pulse_per_circle = 10000\.5 is not "
            r"an integer",
        ),
        ("[motor]\ntime_constant = true\n", r"motor\.time_constant = True is not a number"),
        ("[imu]\nnoise = 1\n", r"imu\.noise = 1 must be true or false"),
        (
            "[chassis]\nmin_speed = 0.9\nmax_speed = 0.5\n",
            r"chassis\.min_speed = 0\.9 must be "
            r"below chassis\.max_speed = 0\.5",
        ),
        ("[rates]\ncontrol_hz = 300\n", r"rates\.control_hz = 300 is invalid; allowed: 100, 200"),
        ("[identity]\nmovebase_type = ''\n", r"identity\.movebase_type = '' is invalid"),
        ("[identity]\nhardware_version = 'v\u00e9'\n", r"identity\.hardware_version"),
        ("[battery]\n", None),
        ("battery = 1\n", r"\[battery\] must be a table"),
        ("[chassis\n", r"invalid TOML"),
    ],
)
def test_validation_errors_are_one_line(tmp_path: Path, text: str, pattern: str | None) -> None:
    if pattern is None:
        assert load_profile(write(tmp_path, text)).battery == {}
        return
    assert re.search(pattern, config_error(tmp_path, text))


def test_integral_float_for_an_integer_field_is_accepted() -> None:
    profile = profile_from_dict({"chassis": {"pulse_per_circle": 4096.0}})
    assert profile.chassis.pulse_per_circle == 4096
    assert isinstance(profile.chassis.pulse_per_circle, int)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match=r"nope\.toml: cannot read profile"):
        load_profile(path)
