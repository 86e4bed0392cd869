"""Legged scenarios (``robot = "legged"``): the library passes on the simulated clock, a
changed scenario fails exactly the expectations it breaks, bad files are one line, and
``lowerbase scenario run`` writes the report and the exit code."""

from __future__ import annotations

import copy
import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from lowerbase.cli import main
from lowerbase.errors import ConfigError
from lowerbase.files import read_toml
from lowerbase.protocol.legged import LocomotionState as S
from lowerbase.scenarios.catalog import find_scenario, library, load_any_scenario
from lowerbase.scenarios.legged import LeggedScenario, legged_scenario_from_dict
from lowerbase.scenarios.legged_run import run_legged_scenario
from lowerbase.scenarios.wheeled import scenario_from_dict
from lowerbase.simloop.legged import LeggedSimLoop

LEGGED = sorted(library("legged"))


def _data(name: str) -> dict[str, Any]:
    return read_toml(library("legged")[name], "scenario")


def test_the_library_has_the_legged_scenarios_apart_from_the_wheeled() -> None:
    assert LEGGED == ["legged_actuator_overtemp", "legged_joystick_handover",
                      "legged_stand_walk_sit", "legged_waypoint_loop"]
    assert not set(LEGGED) & set(library())  # the wheeled runner never sees them
    assert set(LEGGED) <= set(library("all"))
    assert isinstance(load_any_scenario(find_scenario("legged_waypoint_loop")), LeggedScenario)


@pytest.mark.parametrize("name", LEGGED)
def test_every_legged_library_scenario_passes(name: str) -> None:
    scenario = load_any_scenario(library("legged")[name])
    assert isinstance(scenario, LeggedScenario)
    result = run_legged_scenario(scenario)
    failed = [f"{e.title()}: {o.detail}" for e, o in result.outcomes if not o.passed]
    assert result.passed, failed
    assert len(result.outcomes) >= 5 and all(o.status == "passed" for _, o in result.outcomes)


def _run(data: dict[str, Any]) -> dict[str, str]:
    result = run_legged_scenario(legged_scenario_from_dict(data))
    return {e.title(): o.status for e, o in result.outcomes}


def test_without_the_heat_the_overtemperature_expectations_fail() -> None:
    data = _data("legged_actuator_overtemp")
    data["timeline"] = [a for a in data["timeline"] if a["action"] != "heat"]
    statuses = _run(data)
    failed = {k for k, v in statuses.items() if v == "failed"}
    assert failed == {
        "FL_calf reports error 1 and stays above 95 degC (300 s thermal time constant)",
        "fault set True, bit ACTUATOR_OVER_TEMPERATURE during 7.1..16 s", "sits down first",
        "then damped, and stays so (MOTOR_READY refused, ~walk dropped)",
        "stopped speed 0.02 during 10..16 s", "seated"}


def test_a_slower_walk_fails_the_distance_only() -> None:
    data = _data("legged_stand_walk_sit")
    for a in data["timeline"]:
        if a["action"] == "velocity":
            a["vx"] = 0.28
    statuses = _run(data)
    failed = [k for k, v in statuses.items() if v == "failed"]
    assert len(failed) == 1 and failed[0].startswith("walked 0.3 m/s"), statuses


def test_one_lap_fails_the_lap_count() -> None:
    data = copy.deepcopy(_data("legged_waypoint_loop"))
    data["timeline"][2]["repetition"] = 1
    statuses = _run(data)
    assert statuses["two laps walked, mission complete"] == "failed"
    assert statuses["first lap: two laps left"] == "failed"
    assert statuses["answer service set_waypoints, success True, message set waypoint "
                    "success at 5 s"] == "passed"


def test_the_sim_loop_is_the_driver_and_the_lower_computer_on_one_clock() -> None:
    loop = LeggedSimLoop()
    loop.set_goal(S.IN_CONTROL)
    loop.run(4.0)
    assert loop.lower.body.state is S.IN_CONTROL and loop.driver.state is S.IN_CONTROL
    assert loop.goal is None  # reached
    # the first LocomotionStatus (t = 0) brings the link up; the goal's first request goes
    # with the next driver tick (20 ms); from then on 12 replies every ms reach the driver
    assert loop.driver.stats["motor_reply"] == 12 * (4000 - 20)
    assert loop.driver.base_pos[2] == pytest.approx(loop.lower.body.height, abs=1e-3)


@pytest.mark.parametrize(("change", "message"), [
    ({"timeline": [{"at": 1.0, "action": "heat", "joint": "FL_knee", "temperature": 90}]},
     "timeline[0] (at 1 s): joint = 'FL_knee' is not known; one of: FR_hip"),
    ({"timeline": [{"at": 1.0, "action": "walk", "speed": 1}]},
     "timeline[0] (at 1 s): unknown key 'speed'"),
    ({"expect": [{"kind": "state", "equals": "WALKING"}]}, "expect[0] (state): equals"),
    ({"expect": [{"kind": "answer", "service": "set_listen"}]}, "at = the time of the call"),
    ({"timeline": [{"at": 1.0, "action": "set_waypoints", "waypoints": [[1.0]]}]},
     "waypoints[0]: a waypoint is [x, y] or [x, y, z]"),
])
def test_bad_files_are_one_line(change: dict[str, Any], message: str) -> None:
    data = {"scenario": {"robot": "legged", "duration": 5.0}, **change}
    with pytest.raises(ConfigError, match=None) as err:
        legged_scenario_from_dict(data, source="x.toml")
    text = str(err.value)
    assert text.startswith("x.toml: ") and message in text and "\n" not in text


def test_the_wheeled_loader_names_a_legged_file() -> None:
    with pytest.raises(ConfigError, match="a legged scenario"):
        scenario_from_dict({"scenario": {"robot": "legged", "duration": 5.0}})
    with pytest.raises(ConfigError, match="robot = 'hexapod' is not known"):
        scenario_from_dict({"scenario": {"robot": "hexapod", "duration": 5.0}})


def test_scenario_run_writes_the_report_and_the_exit_code(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _data("legged_joystick_handover")
    text = (library("legged")["legged_joystick_handover"]).read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('contains = "pad1"', 'contains = "pad2"'))
    out = tmp_path / "rep"
    assert main(["scenario", "run", str(bad), "--out", str(out)]) == 1
    stdout = capsys.readouterr().out
    assert "FAILED  a second client is refused with the holder's name" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["robot"] == "legged" and summary["counts"] == {
        "passed": len(data["expect"]) - 1, "failed": 1, "skipped": 0}
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    assert suite is not None and suite.get("failures") == "1"
    assert (out / "legged.png").read_bytes().startswith(b"\x89PNG")
    header = (out / "trace.csv").read_text().splitlines()[0].split(",")
    assert {"t", "state", "fault", "x", "laps_done", "temp_FL_calf"} <= set(header)


def test_scenario_run_refuses_what_a_legged_run_cannot_do(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenario", "run", "legged_stand_walk_sit", "--processes"]) == 1
    err = capsys.readouterr().err
    assert "drop --processes" in err and err.count("\n") <= 2
