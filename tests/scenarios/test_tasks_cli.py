"""Task scenarios through the commands: `lowerbase scenario run/list/check` hand files with a
[tasks] table to scenario_tasks; `lowerbase demo` runs the task demo by default (the chassis
demo with --chassis); Ctrl-C leaves a partial report; the task library ships in the package."""

from __future__ import annotations

import fnmatch
import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from lowerbase.cli import main
from lowerbase.reports.tasks import run_and_report
from lowerbase.scenarios.catalog import find_scenario, library, load_any_scenario
from lowerbase.scenarios.tasks import TasksScenario, library_tasks, load_tasks_scenario
from tests.conftest import ROOT

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

FAILING = """[scenario]
duration = 30.0
[world]
map = "empty_room"
[tasks]
unload_time = 2.0
[[timeline]]
at = 1.0
action = "exec_task"
task_id = 7
task_type = 4
direction = 2
mark_no = "R1"
[[expect]]
kind = "task_duration"
task_id = 7
within = [0.0, 3.0]
"""


def test_the_library_has_the_task_scenarios_by_sub_name() -> None:
    lib = library("all")
    assert {f"tasks/{name}" for name in library_tasks()} <= set(lib)
    assert lib["tasks/charging"] != lib["charging"]  # the chassis one keeps its name
    assert "tasks/demo" not in library()  # the wheeled list (run by test_scenarios) has none
    assert isinstance(load_any_scenario(find_scenario("tasks/transport")), TasksScenario)


def test_list_and_check_show_them(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenario", "list"]) == 0
    out = capsys.readouterr().out
    assert "tasks/demo" in out and "transport across the warehouse" in out
    assert main(["scenario", "check", "tasks/demo", "tasks/shift"]) == 0
    assert capsys.readouterr().out.count(": ok") == 2


def test_scenario_run_writes_the_task_report(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rep"
    assert main(["scenario", "run", "tasks/transport", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "scenario tasks_transport: PASSED (4 passed, 0 failed)" in lines[-3]
    assert lines[-2].startswith(f"report: {out / 'index.html'}")
    assert lines[-1].startswith(f"mcap: {out / 'run.mcap'}") and (out / "run.mcap").is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["kind"] == "tasks" and summary["passed"] and "run.log" in summary["files"]
    assert all((out / f).is_file() for f in summary["files"])


def test_a_failing_task_scenario_exits_1_with_the_failure_in_junit(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "mine.toml"
    f.write_text(FAILING)
    assert main(["scenario", "run", str(f), "--out", str(tmp_path / "rep")]) == 1
    assert "FAILED  task 7 takes 0 .. 3 s: took" in capsys.readouterr().out
    suite = ET.parse(tmp_path / "rep" / "junit.xml").getroot().find("testsuite")
    assert suite is not None and suite.get("failures") == "1"


@pytest.mark.parametrize("flags, flag", [(["--realtime"], "--realtime"),
                                         (["--processes"], "--processes"),
                                         (["--record", "x.blf"], "--record")])
def test_wire_options_are_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              flags: list[str], flag: str) -> None:
    out = tmp_path / "rep"
    assert main(["scenario", "run", "tasks/transport", "--out", str(out), *flags]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("lowerbase scenario: error: a task scenario runs in this process")
    assert err[-1].endswith(f"drop {flag}") and not out.exists()


def test_a_bad_task_file_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(FAILING.replace("unload_time = 2.0", "unload_time = 'x'"))
    assert main(["scenario", "run", str(f)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"lowerbase scenario: error: {f}: [tasks]: unload_time must be a number, "
                   "not 'x'"]


def test_ctrl_c_leaves_a_partial_report(tmp_path: Path) -> None:
    class Interrupt:
        def __call__(self, t: float, sim: Any) -> None:
            if t >= 5.0:
                raise KeyboardInterrupt

        def done(self) -> None:
            pass

    scenario = load_tasks_scenario(library_tasks()["transport"])
    result, summary = run_and_report(scenario, tmp_path, Interrupt())
    assert result.interrupted and summary is not None and summary["interrupted"]
    assert 5.0 <= summary["simulated_s"] < 5.5
    assert summary["final"]["truth"]["x"] == pytest.approx(result.sim.world.true_pose()[0],
                                                           abs=1e-4)
    suite = ET.parse(tmp_path / "junit.xml").getroot().find("testsuite")
    assert suite is not None and "interrupted" in ET.tostring(suite, encoding="unicode")


def test_demo_runs_the_task_demo_by_default(monkeypatch: pytest.MonkeyPatch,
                                            tmp_path: Path) -> None:
    import lowerbase.cli.demo as demo

    ran: list[Any] = []
    monkeypatch.setattr(demo, "run_tasks",
                        lambda s, out, debug=False, foxglove=None, mcap=True:
                        ran.append(s) or 0)
    assert main(["demo", "--out", str(tmp_path)]) == 0
    assert ran[0].name == "tasks_demo" and ran[0].source == str(library_tasks()["demo"])


def test_demo_with_a_task_scenario(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--scenario", "tasks/transport", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert (out / "run.mcap").is_file() and "run.mcap" in lines[-1]
    assert lines[0].startswith("lowerbase demo: the whole robot")
    assert lines[-2].startswith("demo passed: 4 of 4 expectations held; task 1 took")
    assert lines[-1].startswith(f"report: {out / 'index.html'}")
    assert json.loads((out / "summary.json").read_text())["passed"] is True


@pytest.mark.parametrize("flags", [["--fast"], ["--chassis", "--scenario", "tasks/demo"],
                                   ["--record", "x.log"]])
def test_demo_chassis_options_with_the_task_demo_are_one_line(
        flags: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--out", str(tmp_path / "d"), *flags]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is for a chassis scenario" in err[0], err
    assert not (tmp_path / "d").exists()


def test_the_task_library_ships_in_the_package() -> None:
    repo, packaged = ROOT / "scenarios" / "tasks", ROOT / "lowerbase" / "scenarios" / "library"
    a = {p.name: p.read_bytes() for p in repo.glob("*.toml")}
    b = {p.name: p.read_bytes() for p in (packaged / "tasks").glob("*.toml")}
    assert a and a == b, "copy scenarios/tasks/*.toml to lowerbase/scenarios/library/tasks/"
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"]["lowerbase"]
    for f in (packaged / "tasks").glob("*.toml"):
        rel = f.relative_to(ROOT / "lowerbase").as_posix()
        assert any(fnmatch.fnmatch(rel, g) and rel.count("/") == g.count("/") for g in globs), rel
