"""The generated woosh_msgs honour the vendor's wire contract: md5sums, fields, serialisation."""

from __future__ import annotations

import hashlib
import io
import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from lowerbase.driver import msggen

# The vendor compatibility contract (shared/woosh_msgs/README.md): ROS1 refuses a connection
# when the md5sums of the two ends differ.
VENDOR_MD5 = {
    "Parameter": "2433376ffe16488ef10a6bb56ed7b4a1",
    "Battery": "6e54ab8d3948bb7be2bfe95e3981bcd0",
    "BMS": "90dcbb86327a728ae02a9e6f441bea51",
    "LED": "3751062b64f080928398f47d67ca9edb",
    "Information": "0f0fb1764f6f87e8178f98663f3ce6a9",
    "RobotStatus": "8f5b2fa7b958d521c2034a877d5d6e07",
    "StepControl": "34371121edf84e6fad9159e3118fc977",
    "StepControlGoal": "b3e8b6166663a200e4731bf7bf0a0ad1",
    "StepControlResult": "9df8bb133137eee8850aa99aa5fc0443",
    "StepControlFeedback": "59ecb722d688505746e4e93aec3b71cb",
    "StepControlActionGoal": "860793efa25c18bc2f8ebde2dde7befe",
    "StepControlActionFeedback": "ab4d26bcc69f8f384d077e77f3437bcb",
    "MoveBaseGoal": "6898a9bfb5890cba54eba620ddd66d15",
    "MoveBaseResult": "d41d8cd98f00b204e9800998ecf8427e",
    "MoveBaseFeedback": "c8db5512d034d0473b5ce1b479373eee",
    "MoveBaseActionGoal": "7c2a5cf759a6ba4c73faddcd6dcd9118",
    "NavigationModeGoal": "6b3a848f30a01f4b14655f430e1f898f",
    "NavigationModeResult": "034a8e20d6a306665e3a5b340fab3f09",
    "NavigationModeFeedback": "3fb824c456a757373a226f6d08071bf0",
    "NavigationModeActionGoal": "aa68dc526f0c056ec8027102ce117b16",
    "Charge": "446f3dbd75e1b0a9087aefb6619cc591",
    "IOModule": "57d5d3fa08644f735300b724008a2b8e",
    "RfRemoteController": "d0bb9831bfdb4ac298154bf7de9a750f",
    "SecondPositionGoal": "2a14afb1e26891f663c3e7245eb4e2b7",
    "SecondPositionResult": "22f9023889607f03709a7d9307c04454",
    "SecondPositionFeedback": "c33f2b45be6b0e2c873f163d3ac6dc2b",
}
VENDOR_SRV_MD5 = {
    "ExecTask": "22be4bcc7dfdb3b89d96a915d92d36fc",
    "ExecTaskRequest": "d13f36fcb97fa2e9e5a8a379bd4a1415",
    "ExecTaskResponse": "15c59eb4ff0555025635504dbca9a711",
}
ACTIONS = ("StepControl", "MoveBase", "NavigationMode", "SecondPosition")
WRAPPERS = ("Action", "ActionGoal", "ActionResult", "ActionFeedback", "Goal", "Result", "Feedback")

# The six messages of the chassis-level driver, field for field (the vendor's definitions win
# over the seed document's tables: Parameter.maxSpeed last, pulsePerCircle uint32; Battery's
# bmsStatus last).
CHASSIS_FIELDS = {
    "Parameter": [
        ("header", "std_msgs/Header"),
        ("wheelPerimeter", "float32"),
        ("wheelDistant", "float32"),
        ("ratioLeft", "float32"),
        ("ratioRight", "float32"),
        ("pulsePerCircle", "uint32"),
        ("maxRPM", "float32"),
        ("minSpeed", "float32"),
        ("maxLinear", "float32"),
        ("maxAngular", "float32"),
        ("joystickMaxLinear", "float32"),
        ("joystickMaxAngular", "float32"),
        ("maxSpeed", "float32"),
    ],
    "Battery": [
        ("header", "std_msgs/Header"),
        ("submodule", "uint8"),
        ("batteryPercentage", "uint8"),
        ("chargeMode", "uint8"),
        ("chargeStatus", "uint8"),
        ("batteryVoltage", "float32"),
        ("batteryCurrent", "float32"),
        ("timeRemain", "float32"),
        ("tempMax", "int8"),
        ("tempMin", "int8"),
        ("capacityRemain", "float32"),
        ("capacityFull", "float32"),
        ("capacityDesign", "float32"),
        ("chargeCycle", "uint16"),
        ("batteryCycle", "uint16"),
        ("cellVoltageMax", "float32"),
        ("cellVoltageMin", "float32"),
        ("bmsStatus", "uint32"),
    ],
    "BMS": [
        ("header", "std_msgs/Header"),
        ("BMSStatus", "uint32"),
        ("current", "float32"),
        ("voltageMax", "float32"),
        ("voltageMin", "float32"),
        ("voltageTotal", "float32"),
        ("temperatureMax", "float32"),
        ("temperatureMin", "float32"),
        ("chargeCycle", "uint16"),
        ("capacityResidue", "float32"),
        ("capacityTotal", "float32"),
        ("switchStatus", "uint8"),
    ],
    "LED": [
        ("submodule", "uint8"),
        ("urgency", "uint8"),
        ("abnormal", "uint8"),
        ("normal", "uint8"),
        ("color", "uint32"),
    ],
    "Information": [
        ("header", "std_msgs/Header"),
        ("hardwareVersion", "string"),
        ("softwareVersion", "string"),
        ("IAPSoftwareVersion", "string"),
        ("movebaseType", "string"),
        ("parameter", "woosh_msgs/Parameter"),
    ],
    "RobotStatus": [
        ("task_id", "uint64"),
        ("task_type", "int32"),
        ("task_state", "int8"),
        ("action_type", "int8"),
        ("action_state", "int8"),
        ("robot_state", "int8"),
        ("robot_mode", "int8"),
        ("work_mode", "int8"),
        ("wait_id", "int32"),
        ("dest", "string"),
        ("msg", "string"),
        ("time", "int32"),
    ],
}


def _all_message_names() -> list[str]:
    names = [p.stem for p in msggen.SOURCE_DIR.glob("*.msg")]
    names += [a + w for a in ACTIONS for w in WRAPPERS]
    return sorted(names)


def _parse_fields(text: str, package: str = "woosh_msgs") -> list[tuple[str, str]]:
    """(name, type) of the fields of a .msg text, types as genpy spells them in _slot_types."""
    builtin = {
        "bool",
        "byte",
        "char",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "float32",
        "float64",
        "string",
        "time",
        "duration",
    }
    fields = []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line or "=" in line:  # blank, comment or constant
            continue
        type_, name = line.split()
        base, bracket, rest = type_.partition("[")
        if base == "Header":
            base = "std_msgs/Header"
        elif base not in builtin and "/" not in base:
            base = f"{package}/{base}"
        fields.append((name, base + bracket + rest))
    return fields


def _source_text(name: str) -> str:
    path = msggen.SOURCE_DIR / f"{name}.msg"
    if path.exists():
        return path.read_text()
    for action in ACTIONS:
        for wrapper in WRAPPERS:
            if name == action + wrapper:
                text = (msggen.SOURCE_DIR / f"{action}.action").read_text()
                return msggen.expand_action(action, text)[name]
    raise KeyError(name)


# -- md5sums ------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(VENDOR_MD5))
def test_md5sum_matches_vendor(woosh_msgs: ModuleType, name: str) -> None:
    cls = getattr(woosh_msgs, name)
    assert cls._type == f"woosh_msgs/{name}"
    assert cls._md5sum == VENDOR_MD5[name]


@pytest.mark.parametrize("name", sorted(VENDOR_SRV_MD5))
def test_service_md5sum_matches_vendor(woosh_srvs: ModuleType, name: str) -> None:
    assert getattr(woosh_srvs, name)._md5sum == VENDOR_SRV_MD5[name]


def test_every_generated_type_is_covered(woosh_msgs: ModuleType) -> None:
    """Every generated type is in the vendor table, or an actionlib wrapper of types that are
    (the wrappers' sums are then fixed by actionlib_msgs' standard definitions)."""
    generated = {
        n
        for n in dir(woosh_msgs)
        if isinstance(getattr(woosh_msgs, n), type) and hasattr(getattr(woosh_msgs, n), "_md5sum")
    }
    assert generated == set(_all_message_names())
    for name in generated - set(VENDOR_MD5):
        assert any(name == a + w for a in ACTIONS for w in WRAPPERS), name


def test_action_wrappers_follow_actionlib(woosh_msgs: ModuleType) -> None:
    """ROS1's md5 of a message with nested types hashes the nested types' md5sums."""
    import actionlib_msgs.msg as alm
    from std_msgs.msg import Header

    for action in ACTIONS:
        result = getattr(woosh_msgs, action + "ActionResult")
        md5_text = (
            f"{Header._md5sum} header\n{alm.GoalStatus._md5sum} status\n"
            f"{getattr(woosh_msgs, action + 'Result')._md5sum} result"
        )
        assert result._md5sum == hashlib.md5(md5_text.encode()).hexdigest()
        assert result.__slots__ == ["header", "status", "result"]
        assert getattr(woosh_msgs, action + "Action").__slots__ == [
            "action_goal",
            "action_result",
            "action_feedback",
        ]


# -- fields -------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(CHASSIS_FIELDS))
def test_chassis_message_fields(woosh_msgs: ModuleType, name: str) -> None:
    cls = getattr(woosh_msgs, name)
    assert list(zip(cls.__slots__, cls._slot_types, strict=True)) == CHASSIS_FIELDS[name]


@pytest.mark.parametrize("name", _all_message_names())
def test_fields_match_definition(woosh_msgs: ModuleType, name: str) -> None:
    cls = getattr(woosh_msgs, name)
    assert list(zip(cls.__slots__, cls._slot_types, strict=True)) == _parse_fields(
        _source_text(name)
    )


def test_constants(woosh_msgs: ModuleType) -> None:
    assert (woosh_msgs.Battery.manualMode, woosh_msgs.Battery.autoMode) == (0, 1)
    assert (woosh_msgs.Battery.discharge, woosh_msgs.Battery.charging) == (0, 1)
    # the vendor's spellings are part of the wire
    g = woosh_msgs.SecondPositionGoal
    assert (g.CANCEL, g.EXCUTE, g.PAUSE, g.RESUM) == (0, 1, 2, 3)
    assert (g.MAG_FRONT, g.RFID_BACK) == (1, 4)
    s = woosh_msgs.StepControlGoal
    assert (s.STRAIGHT, s.ROTATE, s.LATERAL, s.DIAGONALIZE) == (1, 2, 3, 4)


# -- serialisation ------------------------------------------------------------------------

_SAMPLE = {
    "bool": True,
    "byte": -3,
    "char": 200,
    "int8": -100,
    "uint8": 201,
    "int16": -30000,
    "uint16": 60000,
    "int32": -2_000_000_000,
    "uint32": 4_000_000_000,
    "int64": -(2**62),
    "uint64": 2**63 + 5,
    "float32": 1.5,
    "float64": -2.25e10,
    "string": "héllo",
}


def _sample_value(type_: str, depth: int = 0) -> Any:
    import genpy
    from roslib.message import get_message_class

    base, bracket, _ = type_.partition("[")
    if bracket:
        if base in ("uint8", "char"):
            return bytes([1, 2, 250])
        return [_sample_value(base, depth + 1) for _ in range(2)]
    if base in _SAMPLE:
        return _SAMPLE[base]
    if base == "time":
        return genpy.Time(1_700_000_000, 123_456_789)
    if base == "duration":
        return genpy.Duration(-5, 6)
    cls = get_message_class(base)
    assert cls is not None, base
    return _filled(cls, depth + 1)


def _filled(cls: type, depth: int = 0) -> Any:
    slots: list[str] = cls.__slots__  # type: ignore[attr-defined]
    types: list[str] = cls._slot_types  # type: ignore[attr-defined]
    return cls(**{n: _sample_value(t, depth) for n, t in zip(slots, types, strict=True)})


@pytest.mark.parametrize("name", _all_message_names())
def test_round_trip(woosh_msgs: ModuleType, name: str) -> None:
    cls = getattr(woosh_msgs, name)
    msg = _filled(cls)
    buf = io.BytesIO()
    msg.serialize(buf)
    data = buf.getvalue()
    back = cls().deserialize(data)
    assert back == msg
    again = io.BytesIO()
    back.serialize(again)
    assert again.getvalue() == data


def test_service_round_trip(woosh_srvs: ModuleType) -> None:
    for cls in (woosh_srvs.ExecTaskRequest, woosh_srvs.ExecTaskResponse):
        msg = _filled(cls)
        buf = io.BytesIO()
        msg.serialize(buf)
        assert cls().deserialize(buf.getvalue()) == msg


def test_led_bytes_are_exact(woosh_msgs: ModuleType) -> None:
    msg = woosh_msgs.LED(submodule=1, urgency=0, abnormal=0xFF, normal=2, color=0x112233)
    buf = io.BytesIO()
    msg.serialize(buf)
    assert buf.getvalue() == bytes([1, 0, 0xFF, 2, 0x33, 0x22, 0x11, 0x00])


# -- generator and tooling ----------------------------------------------------------------


def test_action_expansion_matches_genaction() -> None:
    msgs = msggen.expand_action("Demo", "int32 a\n---\nint32 b\n---\nint32 c\n")
    assert set(msgs) == {"Demo" + w for w in WRAPPERS}
    autogen = "# ====== DO NOT MODIFY! AUTOGENERATED FROM AN ACTION DEFINITION ======\n"
    assert msgs["DemoGoal"] == autogen + "int32 a\n"
    assert msgs["DemoFeedback"] == autogen + "int32 c\n\n"
    assert msgs["DemoActionGoal"] == (
        autogen + "\nHeader header\nactionlib_msgs/GoalID goal_id\nDemoGoal goal\n"
    )


def test_action_needs_three_sections() -> None:
    from lowerbase.errors import ConfigError

    with pytest.raises(ConfigError):
        msggen.parse_action("int32 a\n---\nint32 b\n")


def test_cli_generates_and_writes_pth(tmp_path: Path, ros: None) -> None:
    site = tmp_path / "site-packages"
    site.mkdir()
    out = tmp_path / "build" / "ros"
    assert msggen.main([str(out), "--pth", str(site)]) == 0
    assert (out / "woosh_msgs" / "__init__.py").is_file()
    assert (out / "woosh_msgs" / "msg" / "__init__.py").is_file()
    assert (out / "woosh_msgs" / "msg" / "_Battery.py").is_file()
    assert (out / "woosh_msgs" / "srv" / "_ExecTask.py").is_file()
    share = out / "share" / "woosh_msgs"
    assert {p.name for p in share.iterdir()} >= {
        "package.xml",
        "manifest.xml",
        "msg",
        "srv",
        "action",
    }
    assert (share / "msg" / "StepControlActionGoal.msg").is_file()
    assert (site / msggen.PTH_NAME).read_text().strip() == str(out.resolve())
    # a second run replaces the output cleanly and leaves no temporary directory behind
    assert msggen.main([str(out), "--no-pth"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["lowerbase_legged_msgs", "lowerbase_msgs",
                                                     "lowerbase_sim_msgs",
                                                     "share", "woosh_msgs"]


def test_cli_reports_a_bad_pth_dir(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], ros: None
) -> None:
    assert msggen.main([str(tmp_path / "out"), "--pth", str(tmp_path / "nope")]) == 1
    assert "not a directory" in capsys.readouterr().err


def test_by_default_it_installs_into_the_active_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, ros: None
) -> None:
    """pip route: no arguments -> OUTDIR inside sys.prefix, .pth into its site-packages."""
    prefix, site = tmp_path / "venv", tmp_path / "venv" / "site-packages"
    site.mkdir(parents=True)
    monkeypatch.setattr(sys, "prefix", str(prefix))
    monkeypatch.setattr(msggen, "site_packages", lambda: site)
    assert msggen.main([]) == 0
    out = prefix / "share" / "lowerbase" / "ros"
    assert (site / msggen.PTH_NAME).read_text().strip() == str(out.resolve())
    # the .pth makes woosh_msgs importable where site-packages is processed
    code = f"import site; site.addsitedir({str(site)!r}); import woosh_msgs.msg as m; " \
        "print(m.Battery._md5sum)"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run([sys.executable, "-S", "-c", code], env=env, capture_output=True,
                          text=True, timeout=60, cwd=tmp_path)
    if done.returncode and "genpy" in done.stderr:  # -S hides the system genpy: allow it back
        done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                              text=True, timeout=60, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[-1] == VENDOR_MD5["Battery"]


def test_ros_env_line_lets_the_ros_tools_find_woosh_msgs_and_the_driver(
    woosh_msgs_build: Path, tmp_path: Path
) -> None:
    """`eval "$(lowerbase ros-env)"` alone (no PYTHONPATH for the tools): rosmsg sees
    woosh_msgs, roslaunch finds the package lowerbase_driver."""
    if shutil.which("rosmsg") is None or shutil.which("roslaunch") is None:
        pytest.skip("rosmsg/roslaunch not installed")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ROS_PACKAGE_PATH")}
    env["ROS_HOME"] = str(tmp_path / "ros_home")
    lb = f"PYTHONPATH={woosh_msgs_build} {sys.executable} -m lowerbase"
    for command in (f"{lb} ros-env", f"PYTHONPATH={woosh_msgs_build} {sys.executable} -m "
                    "lowerbase.driver.msggen --print-env"):
        script = (f'eval "$({command})" && rosmsg md5 woosh_msgs/Parameter && '
                  "roslaunch --files lowerbase_driver driver_base.launch")
        out = subprocess.run(["bash", "-c", script], env=env, capture_output=True, text=True,
                             timeout=60, cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        md5, launch = out.stdout.split()
        assert md5 == VENDOR_MD5["Parameter"]
        assert Path(launch) == Path(msggen.__file__).resolve().parent / "launch" / \
            "driver_base.launch"


def test_ros_env_says_what_to_run_when_nothing_was_generated(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import importlib.util

    from lowerbase.cli import main

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "woosh_msgs" else real(name, *a))
    assert main(["ros-env"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("lowerbase ros-env: error: woosh_msgs is not generated")
    assert "-m lowerbase.driver.msggen" in err and "make" not in err.split()


def test_ros_tools_find_the_package(woosh_msgs_build: Path) -> None:
    """What rosmsg and rostopic/rosbag need: ROS_PACKAGE_PATH alone, no PYTHONPATH.

    Runs the system interpreter the ROS command-line tools use.
    """
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["ROS_PACKAGE_PATH"] = str(woosh_msgs_build / "share")
    env["ROS_HOME"] = str(woosh_msgs_build / "ros_home")
    code = (
        "import roslib.message as m\n"
        "c = m.get_message_class('woosh_msgs/Battery'); print(c._md5sum)\n"
        "print(m.get_service_class('woosh_msgs/ExecTask')._md5sum)\n"
    )
    python = "/usr/bin/python3" if Path("/usr/bin/python3").exists() else sys.executable
    out = subprocess.run(
        [python, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        cwd=woosh_msgs_build.parent,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [VENDOR_MD5["Battery"], VENDOR_SRV_MD5["ExecTask"]]
    rosmsg = shutil.which("rosmsg")
    if rosmsg is None:
        return
    out = subprocess.run(
        [rosmsg, "md5", "woosh_msgs/Parameter"], env=env, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == VENDOR_MD5["Parameter"]


# -- the shared ROS helper ------------------------------------------------------------------


def _conftest() -> ModuleType:
    """tests/driver/conftest.py as a module of its own (pytest owns the name 'conftest')."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "driver_conftest_under_test", Path(__file__).with_name("conftest.py")
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_require_ros_skips_with_a_reason_locally(monkeypatch: pytest.MonkeyPatch) -> None:
    helper = _conftest()
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="no_such_ros_module"):
        helper.require_ros(("no_such_ros_module",))


def test_require_ros_fails_under_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    helper = _conftest()
    monkeypatch.setenv("CI", "true")
    monkeypatch.delenv("LOWERBASE_WITHOUT_ROS", raising=False)
    with pytest.raises(pytest.fail.Exception, match="CI=true requires ROS"):
        helper.require_ros(("no_such_ros_module",))
    helper.require_ros(("json",))  # present: no-op


def test_a_run_without_ros_on_purpose_skips_under_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    helper = _conftest()
    monkeypatch.setenv("CI", "true")
    monkeypatch.setenv("LOWERBASE_WITHOUT_ROS", "1")
    with pytest.raises(pytest.skip.Exception, match="no_such_ros_module"):
        helper.require_ros(("no_such_ros_module",))
