"""lowerbase_legged_msgs: the seed's fields and types, md5sums pinned and recomputed
independently, serialisation round trips, and the ROS tools finding the package."""

from __future__ import annotations

import hashlib
import io
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from lowerbase.driver import msggen
from tests.legged_driver.legged_ros import LEGGED_PKG, legged_build, legged_msgs, legged_srvs

__all__ = ["legged_build", "legged_msgs", "legged_srvs"]  # fixtures used below

SOURCE = msggen.LEGGED.source

# Pinned: a client built against these definitions connects only while they stay the same.
MD5 = {
    "ActuatorState": "fce2e704a4f49e73def65a0d335d1299",
    "RobotState": "307df00f8ca627c5cc7f6f91b628b0ea",
    "Waypoint": "f5220b1e414a3ee0a1c25a30d32a5335",
}
SRV_MD5 = {
    "SetWaypoints": "bc31fd4e376293493280a6686ba69d01",
    "GetWaypoints": "1a6ac4de65c40f36e43b8bdb6fad2bd6",
    "AppendWaypoint": "f9a8d2aad1c7bdae63103f4963e5b245",
    "SetLaserMap": "0575c1db67f0757e8a7a844192f65f44",
    "SetListen": "546971982e3fbbd5a41e60fb6432e357",
}

# The seed's tables (shared/seeds/003), field by field in ROS types (double -> float64)
SEED_FIELDS = {
    "ActuatorState": [("name", "string"), ("position", "float64"), ("velocity", "float64"),
                      ("effort", "float64"), ("status", "uint16"), ("temperature", "float64")],
    "RobotState": [
        ("actuator_states", f"{LEGGED_PKG}/ActuatorState[]"), ("base_pos", "float64[3]"),
        ("base_quat", "float64[4]"), ("base_lin_vel", "float64[3]"),
        ("base_ang_vel", "float64[3]"), ("voltage", "float64"), ("current", "float64"),
        ("max_voltage", "float64"), ("min_voltage", "float64"),
        ("body_temperature", "float64"), ("state", "int32"), ("joy_listen_type", "int32")],
    "Waypoint": [("frame", "string"), ("x", "float64"), ("y", "float64"), ("z", "float64"),
                 ("use_z", "bool")],
}
SEED_SRV_FIELDS = {
    "SetWaypoints": ([("waypoints", f"{LEGGED_PKG}/Waypoint[]"), ("repetition", "uint8"),
                      ("current_index", "uint8")], [("success", "bool"), ("message", "string")]),
    "GetWaypoints": ([], [("success", "bool"), ("message", "string"),
                          ("waypoints", f"{LEGGED_PKG}/Waypoint[]"), ("repetition", "uint8"),
                          ("current_index", "uint8")]),
    "AppendWaypoint": ([("waypoint", f"{LEGGED_PKG}/Waypoint")],
                       [("success", "bool"), ("message", "string")]),
    "SetLaserMap": ([("name", "string"), ("pc", "sensor_msgs/PointCloud2"),
                     ("initial_pose", "geometry_msgs/Pose")],
                    [("success", "bool"), ("message", "string")]),
    "SetListen": ([("data", "string")], [("success", "bool"), ("message", "string")]),
}
STATES = ["COMM_DISABLED", "COMM_ENABLED", "MOTOR_READY", "MOTOR_COMMUTATION", "MOTOR_ENABLED",
          "IN_TEST_MODE", "STANDING_MODE", "IN_CONTROL", "SITDOWN_MODE", "MOTOR_DISABLED"]


# -- an independent md5: ROS1's rule written out (genmsg.compute_md5_text) ------------------

_BUILTIN = {"bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
            "float32", "float64", "string", "time", "duration", "byte", "char"}


def _md5_text(text: str, md5_of: Any) -> str:
    """Constants first ("type NAME=value"), then fields; a field of a message type is written
    as "<md5 of that type> name" (array brackets dropped)."""
    constants, fields = [], []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        type_, rest = line.split(None, 1)
        if "=" in rest:
            name, value = (p.strip() for p in rest.split("=", 1))
            constants.append(f"{type_} {name}={value}")
            continue
        base = re.sub(r"\[\d*\]$", "", type_)
        fields.append(f"{type_} {rest}" if base in _BUILTIN else f"{md5_of(base)} {rest}")
    return "\n".join(constants + fields)


def _md5_of(legged_msgs: ModuleType) -> Any:
    import geometry_msgs.msg
    import sensor_msgs.msg

    def md5_of(base: str) -> str:
        pkg, _, name = base.rpartition("/")
        if pkg == "sensor_msgs":
            return str(getattr(sensor_msgs.msg, name)._md5sum)
        if pkg == "geometry_msgs":
            return str(getattr(geometry_msgs.msg, name)._md5sum)
        text = (SOURCE / f"{name}.msg").read_text()
        return hashlib.md5(_md5_text(text, md5_of).encode()).hexdigest()
    return md5_of


@pytest.mark.parametrize("name", sorted(MD5))
def test_message_md5sum_is_pinned_and_recomputed(legged_msgs: ModuleType, name: str) -> None:
    cls = getattr(legged_msgs, name)
    assert cls._md5sum == MD5[name]
    assert _md5_of(legged_msgs)(f"{LEGGED_PKG}/{name}") == MD5[name]
    assert cls._type == f"{LEGGED_PKG}/{name}"


@pytest.mark.parametrize("name", sorted(SRV_MD5))
def test_service_md5sum_is_pinned_and_recomputed(legged_msgs: ModuleType,
                                                 legged_srvs: ModuleType, name: str) -> None:
    cls = getattr(legged_srvs, name)
    assert cls._md5sum == SRV_MD5[name]
    request, response = (SOURCE / f"{name}.srv").read_text().split("\n---\n")
    md5_of = _md5_of(legged_msgs)
    text = _md5_text(request, md5_of) + _md5_text(response, md5_of)
    assert hashlib.md5(text.encode()).hexdigest() == SRV_MD5[name]
    assert cls._request_class._md5sum == hashlib.md5(
        _md5_text(request, md5_of).encode()).hexdigest()


def test_every_definition_is_covered() -> None:
    assert {p.stem for p in SOURCE.glob("*.msg")} == set(MD5)
    assert {p.stem for p in SOURCE.glob("*.srv")} == set(SRV_MD5)


@pytest.mark.parametrize("name", sorted(SEED_FIELDS))
def test_message_fields_are_the_seeds(legged_msgs: ModuleType, name: str) -> None:
    cls = getattr(legged_msgs, name)
    assert list(zip(cls.__slots__, cls._slot_types, strict=True)) == SEED_FIELDS[name]


@pytest.mark.parametrize("name", sorted(SEED_SRV_FIELDS))
def test_service_fields_are_the_seeds(legged_srvs: ModuleType, name: str) -> None:
    cls = getattr(legged_srvs, name)
    request, response = SEED_SRV_FIELDS[name]
    for cls_, fields in ((cls._request_class, request), (cls._response_class, response)):
        assert list(zip(cls_.__slots__, cls_._slot_types, strict=True)) == fields


def test_state_and_joy_constants(legged_msgs: ModuleType) -> None:
    rs = legged_msgs.RobotState
    assert [getattr(rs, s) for s in STATES] == list(range(10))
    assert (rs.JOY, rs.VEL_CMD, rs.NONE) == (0, 1, 2)


def test_robot_state_round_trip(legged_msgs: ModuleType) -> None:
    m = legged_msgs
    msg = m.RobotState(
        actuator_states=[m.ActuatorState(name=f"FR_{j}", position=0.1 * i, velocity=-i,
                                         effort=2.5, status=i, temperature=40.0 + i)
                         for i, j in enumerate(["hip", "thigh", "calf"] * 4)],
        base_pos=[1.0, 2.0, 0.3], base_quat=[0.0, 0.0, 0.0, 1.0], base_lin_vel=[0.5, 0, 0],
        base_ang_vel=[0, 0, 0.2], voltage=48.1, current=-3.5, max_voltage=54.6,
        min_voltage=42.0, body_temperature=35.5, state=7, joy_listen_type=1)
    buf = io.BytesIO()
    msg.serialize(buf)
    back = m.RobotState().deserialize(buf.getvalue())
    assert back == msg
    # fixed arrays carry no length prefix: 12 actuators then 13 doubles + 5 doubles + 2 int32
    per_actuator = [4 + len(a.name) + 8 * 3 + 2 + 8 for a in msg.actuator_states]
    assert len(buf.getvalue()) == 4 + sum(per_actuator) + 8 * 13 + 8 * 5 + 4 * 2


def test_ros_tools_find_the_package(legged_build: Path) -> None:
    """ROS_PACKAGE_PATH alone (no PYTHONPATH), with the interpreter the ROS tools run."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["ROS_PACKAGE_PATH"] = str(legged_build / "share")
    env["ROS_HOME"] = str(legged_build / "ros_home")
    code = ("import roslib.message as m\n"
            f"print(m.get_message_class('{LEGGED_PKG}/RobotState')._md5sum)\n"
            f"print(m.get_service_class('{LEGGED_PKG}/SetLaserMap')._md5sum)\n")
    python = "/usr/bin/python3" if Path("/usr/bin/python3").exists() else sys.executable
    out = subprocess.run([python, "-c", code], env=env, capture_output=True, text=True,
                         timeout=60, cwd=legged_build)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [MD5["RobotState"], SRV_MD5["SetLaserMap"]]
    for tool, type_, expected in (("rosmsg", "RobotState", MD5["RobotState"]),
                                  ("rossrv", "SetWaypoints", SRV_MD5["SetWaypoints"])):
        if shutil.which(tool) is None:
            continue
        done = subprocess.run([tool, "md5", f"{LEGGED_PKG}/{type_}"], env=env,
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == expected


def test_ros_env_names_the_legged_package(legged_build: Path) -> None:
    paths = msggen.ros_package_path()
    assert paths[0] == legged_build / "share"
    assert (paths[0] / LEGGED_PKG / "package.xml").is_file()
    xml = (paths[0] / LEGGED_PKG / "package.xml").read_text()
    assert f"<name>{LEGGED_PKG}</name>" in xml and "<depend>sensor_msgs</depend>" in xml


def test_a_missing_dependency_names_the_debian_package(tmp_path: Path) -> None:
    from lowerbase.errors import RosUnavailableError

    with pytest.raises(RosUnavailableError, match="install ros-no-such-msgs"):
        msggen.find_dependency_msg_dirs(("no_such_msgs",))
