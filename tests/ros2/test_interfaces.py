"""The interface packages built by ``make ros2`` (lowerbase.ros2.interfaces), in a real rclpy
process of the ROS 2 venv: woosh_msgs and lowerbase_legged_msgs keep the ROS 1 field names,
order and types (Header as std_msgs/Header), tf2_msgs and nav2_msgs those of their definitions,
and every type round-trips through rclpy.serialization (CDR)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from lowerbase.ros2.interfaces import PACKAGES, InterfacePackage, definition_files, translate_ros1
from tests.ros2.conftest import Ros2

#: .msg types as rclpy's get_fields_and_field_types() names them
_SCALARS = {"float32": "float", "float64": "double", "byte": "octet", "char": "uint8",
            "bool": "boolean"}


def expected_fields(pkg: str, text: str) -> list[tuple[str, str]]:
    fields = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line or "=" in line:
            continue
        kind, name = line.split()[:2]
        m = re.match(r"^([\w/]+)(\[(\d*)\])?$", kind)
        assert m, line
        base = _SCALARS.get(m.group(1), m.group(1))
        if base[0].isupper():
            base = f"{pkg}/{base}"
        if m.group(2) is None:
            fields.append((name, base))
        elif m.group(3):
            fields.append((name, f"{base}[{m.group(3)}]"))
        else:
            fields.append((name, f"sequence<{base}>"))
    return fields


def expectations(pkg: InterfacePackage) -> dict[str, list[tuple[str, str]]]:
    parts = {"msg": (None,), "srv": ("Request", "Response"), "action": ("Goal", "Result",
                                                                          "Feedback")}
    out = {}
    for rel in definition_files(pkg):
        kind = rel.suffix[1:]
        text = (pkg.source / rel).read_text(encoding="utf-8")
        if pkg.ros1:
            text = translate_ros1(text)
        sections = re.split(r"^---\s*$", text, flags=re.M)
        for part, section in zip(parts[kind], sections, strict=True):
            key = f"{pkg.name}/{kind}/{rel.stem}" + (f"_{part}" if part else "")
            out[key] = expected_fields(pkg.name, section)
    return out


def _specs(pkg: InterfacePackage) -> list[str]:
    return sorted({f"{pkg.name}/{rel.suffix[1:]}/{rel.stem}" for rel in definition_files(pkg)})


@pytest.mark.parametrize("pkg", PACKAGES, ids=[p.name for p in PACKAGES])
def test_layout_and_roundtrip(ros2: Ros2, pkg: InterfacePackage) -> None:
    got = ros2.run_json("ros2_layout.py", *_specs(pkg))
    want = expectations(pkg)
    assert sorted(got) == sorted(want)
    for key, fields in want.items():
        assert [tuple(f) for f in got[key]["fields"]] == fields, key
        assert got[key]["roundtrip"], key


def test_known_types_present(ros2: Ros2) -> None:
    """The types the ROS 2 face uses, by their ROS 2 names."""
    got = ros2.run_json("ros2_layout.py", "woosh_msgs/msg/Battery", "tf2_msgs/msg/TFMessage",
                        "nav2_msgs/action/NavigateToPose", "nav2_msgs/action/ComputePathToPose")
    battery = dict(got["woosh_msgs/msg/Battery"]["fields"])
    assert battery["header"] == "std_msgs/Header" and battery["batteryPercentage"] == "uint8"
    assert dict(got["tf2_msgs/msg/TFMessage"]["fields"]) == {
        "transforms": "sequence<geometry_msgs/TransformStamped>"}
    goal = dict(got["nav2_msgs/action/NavigateToPose_Goal"]["fields"])
    assert goal == {"pose": "geometry_msgs/PoseStamped", "behavior_tree": "string"}
    result = dict(got["nav2_msgs/action/ComputePathToPose_Result"]["fields"])
    assert result["path"] == "nav_msgs/Path" and result["error_code"] == "uint16"


def test_definitions_found() -> None:
    for pkg in PACKAGES:
        assert definition_files(pkg), pkg.name
        assert all(isinstance(p, Path) for p in definition_files(pkg))
