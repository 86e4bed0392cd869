"""Scenarios: validation, the expectation engine, the library, reports, recording, replay."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import can
import numpy as np
import pytest

from lowerbase.cli import main
from lowerbase.errors import ConfigError
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.scenarios.catalog import library, library_dirs
from lowerbase.scenarios.expect import COLUMNS, PoseNear, StatusBitIs, Stopped, Trace
from lowerbase.scenarios.replay import BusRecorder, replay
from lowerbase.scenarios.runner import SimHarness, run_scenario, run_simulated
from lowerbase.scenarios.wheeled import load_scenario, scenario_from_dict

ROOT = Path(__file__).resolve().parents[2]

SHORT = """
[scenario]
name = "short"
duration = 4.0

[[timeline]]
at = 1.0
action = "twist"
linear = 0.5
duration = 2.0

[[expect]]
kind = "moving"
during = [2.0, 3.0]
speed = 0.45

[[expect]]
kind = "stopped"
after = 3.0
within = 0.6
"""


def write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# -- validation --------------------------------------------------------------------------------


@pytest.mark.parametrize(("text", "message"), [
    ("[scenario]\nduration = 1\n[initals]\n", "unknown key 'initals'; did you mean initial"),
    ("[scenario]\nname = 'x'\n", "[scenario]: missing duration"),
    ("[scenario]\nduration = 'long'\n", "duration must be a number"),
    ("[scenario]\nduration = 5\n[[timeline]]\nat = 1\naction = 'twist'\nlinaer = 1\n"
     "duration = 1\n", "timeline[0] (at 1 s): unknown key 'linaer'; did you mean linear?"),
    ("[scenario]\nduration = 5\n[[timeline]]\nat = 9\naction = 'estop'\n",
     "timeline[0]: at = 9 is outside 0..5"),
    ("[scenario]\nduration = 5\n[[timeline]]\nat = 1\nfault = 'stall:middle'\n",
     "timeline[0] (at 1 s): fault 'stall:middle': the wheel must be left or right"),
    ("[scenario]\nduration = 5\n[[timeline]]\nat = 1\nfault = 'stall:left@2'\n",
     "give the start as at = ..."),
    ("[scenario]\nduration = 5\n[[timeline]]\nat = 1\naction = 'jump'\n",
     "action = 'jump' is not known"),
    ("[scenario]\nduration = 5\n[[expect]]\nkind = 'status'\nbit = 'WATCHDOG'\nat = 1\n",
     "unknown StatusCode bit 'WATCHDOG'; did you mean WATCHDOG_STOP?"),
    ("[scenario]\nduration = 5\n[[expect]]\nkind = 'soc'\nmin = 50\nmax = 40\n",
     "expect[0] (soc): min 50 > max 40"),
    ("[scenario]\nduration = 5\n[[expect]]\nkind = 'stopped'\nafter = 1\nwithin = true\n",
     "within must be a number"),
    ("[scenario]\nduration = 5\n[[expect]]\nkind = 'state'\nequals = 'Runing'\n",
     "equals = 'Runing' is not known"),
    ("[scenario\nduration = 5\n", "invalid TOML"),
])
def test_validation_errors_are_one_line_config_errors(tmp_path: Path, text: str,
                                                      message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    text_ = str(info.value)
    assert message in text_
    assert text_.startswith(str(path))
    assert "\n" not in text_


def test_cli_prints_one_line_for_a_bad_scenario(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, "[scenario]\nduration = 5\nspeed = 3\n")
    assert main(["scenario", "run", str(path), "--out", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown key 'speed'" in err[0]
    assert main(["scenario", "run", "no-such-scenario"]) == 1
    assert "library" in capsys.readouterr().err


def test_a_profile_relative_to_the_scenario(tmp_path: Path) -> None:
    from lowerbase.firmware_model.profile import default_profile_path

    profile = tmp_path / "robots" / "slow.toml"
    profile.parent.mkdir()
    profile.write_text(default_profile_path().read_text().replace(
        "max_linear = 1.2 ", "max_linear = 0.3 "), encoding="utf-8")
    text = SHORT.replace('duration = 4.0', 'duration = 4.0\nprofile = "robots/slow.toml"')
    result = run_simulated(load_scenario(write(tmp_path, text)))
    assert max(result.trace["truth_v"]) == pytest.approx(0.3, abs=0.01)  # clipped: slow robot
    with pytest.raises(ConfigError, match=r"profile .*nowhere\.toml' not found"):
        load_scenario(write(tmp_path, text.replace("robots/slow.toml", "nowhere.toml")))


def test_a_fault_spec_keeps_its_duration() -> None:
    s = scenario_from_dict({"scenario": {"duration": 5}, "timeline": [
        {"at": 1, "fault": "stall:left+2"}, {"at": 2, "fault": "drop:0.1", "duration": 1.5}]})
    assert [f.end for f in s.faults] == [3.0, 3.5]
    assert [f.spec_from_boot() for f in s.faults] == ["stall:left@1+2", "drop:0.1@2+1.5"]


# -- the expectation engine on hand-made traces ------------------------------------------------


def _trace(rows: list[dict[str, float]]) -> Trace:
    trace = Trace()
    for row in rows:
        trace.append(row)
    return trace


def test_stopped_holds_from_the_deadline_on() -> None:
    # |v| falls by 0.2 m/s per 0.1 s from 1 m/s at t = 1
    rows = [{"t": k / 10, "truth_v": max(0.0, 1.0 - 0.2 * max(0, k - 10)), "truth_w": 0.0}
            for k in range(40)]
    trace = _trace(rows)
    assert Stopped(after=1.0, within=0.6).evaluate(trace).status == "passed"
    outcome = Stopped(after=1.0, within=0.3).evaluate(trace)
    assert outcome.status == "failed" and "t=1.40 s" in outcome.detail
    rows[30]["truth_v"] = 0.5  # moves again later
    assert Stopped(after=1.0, within=0.6).evaluate(_trace(rows)).status == "failed"
    assert Stopped(after=1.0, within=0.6, until=2.5).evaluate(_trace(rows)).status == "passed"


def test_status_bit_at_during_and_sometime() -> None:
    bit = int(StatusBit.WATCHDOG_STOP)
    trace = _trace([{"t": k / 10, "status": bit if 10 <= k < 20 else 0} for k in range(30)])
    assert StatusBitIs(bit=StatusBit.WATCHDOG_STOP, during=(1.0, 1.9)).evaluate(trace).passed
    assert not StatusBitIs(bit=StatusBit.WATCHDOG_STOP, during=(1.0, 2.0)).evaluate(
        trace).passed
    assert StatusBitIs(bit=StatusBit.WATCHDOG_STOP, during=(0.0, 2.5),
                       sometime=True).evaluate(trace).passed
    assert StatusBitIs(bit=StatusBit.WATCHDOG_STOP, set=False, at=2.5).evaluate(trace).passed


def test_pose_error_and_missing_truth() -> None:
    row = {"t": 1.0, "truth_x": 1.0, "truth_y": 0.0, "truth_yaw": 0.0,
           "ekf_x": 1.03, "ekf_y": 0.04, "ekf_yaw": 0.01}
    assert PoseNear(within=0.0501).evaluate(_trace([row])).passed  # 5 cm
    assert not PoseNear(within=0.049).evaluate(_trace([row])).passed
    assert not PoseNear(within=1.0, yaw_within=0.005).evaluate(_trace([row])).passed
    no_truth = {k: v for k, v in row.items() if not k.startswith("truth")}
    assert PoseNear(within=0.05).evaluate(_trace([no_truth])).status == "skipped"


# -- the library -------------------------------------------------------------------------------


def test_the_library_covers_the_chassis_behaviours() -> None:
    names = set(library())
    assert {"loop", "watchdog", "estop", "low_battery", "charging", "wheel_slip",
            "encoder_fault", "bms_link_lost", "reboot", "demo"} <= names


def test_the_packaged_copy_matches_the_repository() -> None:
    repo, packaged = ROOT / "scenarios", ROOT / "lowerbase" / "scenarios" / "library"
    assert library_dirs()[0] == repo
    a = {p.name: p.read_bytes() for p in repo.glob("*.toml")}
    b = {p.name: p.read_bytes() for p in packaged.glob("*.toml")}
    assert a == b, "copy scenarios/*.toml to lowerbase/scenarios/library/"


@pytest.mark.parametrize("name", sorted(library()))
def test_every_library_scenario_passes(name: str) -> None:
    result = run_simulated(load_scenario(library()[name]))
    failed = [f"{e.title()}: {o.detail}" for e, o in result.outcomes if not o.passed]
    assert result.passed, failed
    assert result.outcomes and all(o.status == "passed" for _, o in result.outcomes)


# -- run, report, exit code --------------------------------------------------------------------


def test_a_failing_expectation_fails_the_run(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    text = SHORT + '\n[[expect]]\nkind = "stopped"\nname = "never moves"\nafter = 0.5\n' \
                   'within = 0.1\n'
    out = tmp_path / "report"
    assert main(["scenario", "run", str(write(tmp_path, text)), "--out", str(out)]) == 1
    stdout = capsys.readouterr().out
    assert "FAILED  never moves: still moving" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["passed"] is False and summary["counts"] == {
        "passed": 2, "failed": 1, "skipped": 0}
    failed = [e for e in summary["expectations"] if e["status"] == "failed"]
    assert [e["name"] for e in failed] == ["never moves"]
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    assert suite is not None and suite.get("failures") == "1" and suite.get("tests") == "3"
    failures = [c.get("name") for c in suite.iter("testcase") if c.find("failure") is not None]
    assert failures == ["never moves"]


def test_the_report_files(tmp_path: Path) -> None:
    out = tmp_path / "report"
    assert main(["scenario", "run", str(write(tmp_path, SHORT)), "--out", str(out)]) == 0
    for name in ("trajectory.png", "velocities.png", "battery.png", "status.png"):
        data = (out / name).read_bytes()
        assert data.startswith(b"\x89PNG\r\n\x1a\n") and len(data) > 10_000, name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["passed"] is True and summary["mode"] == "simulated"
    assert summary["final"]["truth"]["x"] == pytest.approx(1.0, abs=0.1)
    assert summary["final"]["odom_error_m"] < 0.02
    root = ET.parse(out / "junit.xml").getroot()
    assert root.tag == "testsuites" and root.find("testsuite").get("failures") == "0"  # type: ignore[union-attr]
    header = (out / "trace.csv").read_text().splitlines()[0]
    assert header.startswith("t [s],truth_x [m]")
    assert "index.html" in summary["files"] and (out / "index.html").is_file()
    assert (out / "run.log").is_file()


def test_initial_pose_starts_truth_and_odometry_there() -> None:
    s = scenario_from_dict({
        "scenario": {"duration": 3}, "initial": {"x": 2.0, "y": -1.0, "yaw": math.pi / 2},
        "timeline": [{"at": 1, "action": "twist", "linear": 0.5, "duration": 1}]})
    trace = run_simulated(s).trace
    assert trace["truth_y"][-1] == pytest.approx(-0.5, abs=0.05)
    assert trace["truth_x"][-1] == pytest.approx(2.0, abs=0.01)
    for prefix in ("raw", "ekf"):
        assert math.hypot(trace[f"{prefix}_x"][-1] - trace["truth_x"][-1],
                          trace[f"{prefix}_y"][-1] - trace["truth_y"][-1]) < 0.01


# -- recording and replay ----------------------------------------------------------------------


def test_record_log_asc_blf(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "run.log"
    assert main(["scenario", "run", str(write(tmp_path, SHORT)), "--out",
                 str(tmp_path / "r"), "--record", str(log)]) == 0
    capsys.readouterr()
    frames = sum(1 for _ in can.LogReader(str(log)))
    assert frames > 1000
    assert main(["decode", str(log)]) == 0
    captured = capsys.readouterr()
    assert f"# {frames} frames, {frames} decoded" in captured.err
    assert "WheelFeedback" in captured.out and "MotionCommand" in captured.out
    first = log.read_text().splitlines()[0]
    assert first.startswith("(0.000000) can0 090#")  # simulated time, boot-up Heartbeat
    s = load_scenario(write(tmp_path, SHORT))
    for suffix in (".asc", ".blf"):
        path = tmp_path / f"run{suffix}"
        with BusRecorder(path) as rec:
            run_simulated(s, tap=rec)
        assert rec.frames == frames
        assert sum(1 for _ in can.LogReader(str(path))) == frames


@pytest.mark.parametrize("suffix", [".log", ".blf"])
def test_replay_reproduces_the_odometry(tmp_path: Path, suffix: str) -> None:
    s = load_scenario(library()["reboot"])  # a reboot in the middle: re-baselining too
    path = tmp_path / f"run{suffix}"
    with BusRecorder(path) as rec:
        harness = SimHarness(s, tap=rec)
        run_scenario(s, harness)
    original = harness.driver
    replayed = replay(path).driver
    assert replayed.reboots == 1
    assert original.odometry is not None and replayed.odometry is not None
    for a, b in ((original.odometry.x, replayed.odometry.x),
                 (original.odometry.y, replayed.odometry.y),
                 (original.odometry.yaw, replayed.odometry.yaw),
                 *zip(original.ekf.pose, replayed.ekf.pose, strict=True)):
        assert a == pytest.approx(b, abs=1e-6)


def test_replay_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "run.log"
    with BusRecorder(log) as rec:
        run_simulated(load_scenario(write(tmp_path, SHORT)), tap=rec)
    out = tmp_path / "replay"
    assert main(["scenario", "replay", str(log), "--out", str(out)]) == 0
    assert "final /odom_raw x +1.0" in capsys.readouterr().out
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert json.loads((out / "summary.json").read_text())["frames"] == rec.frames
    assert main(["scenario", "replay", str(tmp_path / "none.log")]) == 1
    assert main(["scenario", "replay", str(tmp_path / "x.mp4")]) == 1


# -- the demo and the other commands -----------------------------------------------------------


def test_demo_chassis_fast(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--chassis", "--fast", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-2].startswith("demo passed:") and "cm from the ground truth" in lines[-2]
    assert lines[-1].startswith(f"report: {out / 'index.html'}")
    assert json.loads((out / "summary.json").read_text())["passed"] is True


def test_list_and_check(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenario", "list"]) == 0
    assert "watchdog" in capsys.readouterr().out
    assert main(["scenario", "check", *sorted(library())]) == 0
    assert capsys.readouterr().out.count(": ok") == len(library())


def test_in_process_scenarios_are_refused_over_processes(tmp_path: Path) -> None:
    from lowerbase.scenarios.demo import check_over_bus

    with pytest.raises(ConfigError, match="charger at t=2 s"):
        check_over_bus(load_scenario(library()["charging"]))
    check_over_bus(load_scenario(library()["demo"]))



def test_trace_grows_past_its_capacity_and_keeps_every_sample() -> None:
    trace = Trace(capacity=4)
    for k in range(11):
        trace.append({"t": k * 0.05, "soc": 80 - k, "unknown_column": 1.0})
    assert len(trace) == 11
    np.testing.assert_allclose(trace["t"], [k * 0.05 for k in range(11)])
    assert trace["soc"].tolist() == [80.0 - k for k in range(11)]
    assert np.isnan(trace["voltage"]).all() and not trace.has("voltage")
    d = trace.as_dict()
    assert set(d) == set(COLUMNS) and d["soc"][-1] == 70.0 and len(d["t"]) == 11
