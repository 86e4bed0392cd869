"""The conformance suite: its pure parts, the emulator's defects on the simulated clock, and
``lowerbase conformance`` against ``lowerbase emulate`` processes (clean and defective)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from lowerbase.cli import main
from lowerbase.conformance import (
    Check,
    CheckResult,
    Outcome,
    Report,
    Status,
    bursts,
    counter_steps,
    cycle_stats,
    failed,
    junit_xml,
    passed,
    periodic_lower_messages,
    registry,
    select,
    shared_cycles,
    skipped,
)
from lowerbase.errors import ConfigError
from lowerbase.firmware_model.faults import parse_fault
from lowerbase.firmware_model.mcu import RobotState
from lowerbase.firmware_model.sim import SimRig
from lowerbase.protocol.codec import default_codec
from tests.conformance.cli_results import run_conformance
from tests.conftest import LOADED_HOST, bus_cli_args

CODEC = default_codec()
ALL_IDS = [c.id for c in registry(CODEC)]

# -- the registry and its pure parts --------------------------------------------------------------


def test_registry_covers_the_catalog() -> None:
    assert len(ALL_IDS) == len(set(ALL_IDS))
    for msg in periodic_lower_messages(CODEC):
        for aspect in ("present", "dlc", "range", "cycle"):
            assert f"frame.{msg.name}.{aspect}" in ALL_IDS
        assert (f"frame.{msg.name}.counter" in ALL_IDS) == msg.has_counter
    assert "frame.StatusCode.counter" not in ALL_IDS  # all 64 bits are the code
    assert {"safety.watchdog", "safety.estop", "param.out_of_range", "version.all",
            "robust.unknown_id"} <= set(ALL_IDS)


def test_select_by_patterns() -> None:
    checks = registry(CODEC)
    assert [c.id for c in select(checks, [])] == ALL_IDS
    chosen = [c.id for c in select(checks, ["frame.Heartbeat.*,safety.watchdog", "param.read"])]
    assert chosen == ["param.read", "frame.Heartbeat.present", "frame.Heartbeat.dlc",
                      "frame.Heartbeat.range", "frame.Heartbeat.cycle",
                      "frame.Heartbeat.counter", "frame.Heartbeat.uptime", "safety.watchdog"]
    assert select(checks, ["nothing.*"]) == []


def test_counter_steps_and_shared_cycles() -> None:
    assert counter_steps([14, 15, 0, 1]) == (3, 0, "")
    assert counter_steps([3, 3, 4, 6]) == (3, 2, "3 -> 3")
    # WheelFeedback: both wheels share the cycle's counter (first and last cycle may be partial)
    rows = [(1, 7), (0, 8), (1, 8), (0, 9), (1, 9), (0, 10)]
    assert shared_cycles(rows) == ([7, 8, 9, 10], 0)
    stuck = [(0, 0), (1, 0), (0, 0), (1, 0)]
    assert shared_cycles(stuck) == ([0, 0], 0)
    assert counter_steps(shared_cycles(stuck)[0])[1] == 1
    lost = [(0, 1), (1, 1), (0, 2), (0, 3), (1, 3), (0, 4), (1, 4)]  # right frame of 2 lost
    assert shared_cycles(lost)[1] == 1


def test_cycle_statistics_and_bursts() -> None:
    mean, gap = cycle_stats([0.0, 0.1, 0.2, 0.45])
    assert mean == pytest.approx(0.15) and gap == pytest.approx(0.25)
    stamps = [0.0, 0.001, 0.002, 1.0, 1.001, 2.0005, 2.002]
    assert bursts(stamps, 1.0) == [0.0, 1.0, 2.0005]


def _cycle_run(gap: float, overruns_after: int, boot_after: int = 1) -> Outcome:
    """frame.MotionState.cycle on 5 s of 20 ms frames (bus stamps) with one stall of ``gap``
    [s] at 2.01 s, and Heartbeats every 0.5 s whose Overruns step to ``overruns_after`` (and
    BootCounter to ``boot_after``) after the stall."""
    from types import SimpleNamespace

    from lowerbase.conformance.client import RawFrame
    from lowerbase.conformance.core import Settings
    from lowerbase.conformance.frames import check_cycle

    motion, heartbeat = CODEC.message("MotionState"), CODEC.message("Heartbeat")
    stamps = [round(0.02 * k, 6) for k in range(250)]
    stamps = [t if t < 2.0 else t + gap - 0.02 for t in stamps]
    frames = [RawFrame(t, 1000.0 + t, motion.encode({"Linear": 0.0, "Angular": 0.0,
                                                     "Counter": k % 16}))
              for k, t in enumerate(stamps)]
    beats = [RawFrame(t, 1000.0 + t, heartbeat.encode({
        "ProtocolVersion": 1, "Uptime": t, "Counter": k % 16,
        "BootCounter": 1 if t < 2.0 else boot_after,
        "Overruns": 0 if t < 2.0 else overruns_after})) for k, t in
        enumerate(0.5 * k + (gap if k >= 5 else 0.0) for k in range(12))]
    raw = {motion.frame_id: frames, heartbeat.frame_id: beats}
    ctx = SimpleNamespace(codec=CODEC, settings=Settings(),
                          observation=lambda msg: raw[msg.frame_id],
                          client=SimpleNamespace(raw_frames=lambda fid: raw[fid]))
    return check_cycle(motion)(ctx)  # type: ignore[arg-type]


def test_a_gap_across_a_slip_the_lower_computer_reports_is_shown_not_judged() -> None:
    """A 300 ms stall of a lower computer that counted it (Heartbeat.Overruns stepped: its
    time slipped) is reported and left out, as frame.Heartbeat.uptime leaves it out; the same
    stall without its report, or across a reboot, fails the gap."""
    told = _cycle_run(0.3, overruns_after=1)
    assert told.status is Status.PASS, told.detail
    assert told.measured["slipped_gaps"] == 1 and told.measured["max_gap_ms"] == 20.0
    assert told.measured["mean_ms"] == pytest.approx(20.0)
    assert "1 gap up to 300 ms across a slip the lower computer reported" in told.detail
    silent = _cycle_run(0.3, overruns_after=0)
    assert silent.status is Status.FAIL and "gap above 100 ms" in silent.detail
    assert silent.measured["slipped_gaps"] == 0
    rebooted = _cycle_run(0.3, overruns_after=1, boot_after=2)
    assert rebooted.status is Status.FAIL
    # a gap within the limit never asks the Heartbeats
    assert _cycle_run(0.08, overruns_after=0).status is Status.PASS


def _report() -> Report:
    def check(cid: str) -> Check:
        return Check(cid, f"{cid} works", lambda _: passed())

    results = (
        CheckResult(check("frame.Heartbeat.cycle"), passed("mean 500 ms", mean_ms=500.0), 0.1),
        CheckResult(check("safety.watchdog"), failed("no <WatchdogStop> & co"), 1.5),
        CheckResult(check("safety.estop"), skipped("--no-motion"), 0.0),
        CheckResult(check("robust.bad_dlc"), Outcome(Status.ERROR, "OSError: gone"), 0.2),
    )
    return Report(results, 2.0)


def test_junit_xml_is_valid_and_complete(tmp_path: Path) -> None:
    report = _report()
    assert not report.ok and report.failed_ids() == {"safety.watchdog", "robust.bad_dlc"}
    path = tmp_path / "junit.xml"
    junit_xml(report).write(path, encoding="utf-8", xml_declaration=True)
    root = ET.parse(path).getroot()
    assert root.tag == "testsuites"
    suite = root.find("testsuite")
    assert suite is not None
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors"),
            suite.get("skipped")) == ("4", "1", "1", "1")
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    assert cases["frame.Heartbeat.cycle"].get("classname") == (
        "lowerbase.conformance.frame.Heartbeat")
    assert cases["frame.Heartbeat.cycle"].findtext("system-out") == "mean_ms = 500.0"
    failure = cases["safety.watchdog"].find("failure")
    assert failure is not None and failure.get("message") == "no <WatchdogStop> & co"
    assert cases["safety.estop"].find("skipped") is not None
    assert cases["robust.bad_dlc"].find("error") is not None


def test_cli_list_and_bad_options(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["conformance", "--list", "--only", "safety.*"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith("safety.reboot")
    assert all(line.startswith("safety.") for line in out.splitlines())
    assert main(["conformance", "--only", "nosuch.*"]) == 1
    err = capsys.readouterr().err
    assert err.strip() == ("lowerbase conformance: error: no check matches --only nosuch.* "
                           "(see --list)")
    assert main(["conformance", "--observe", "0.1", "-i", "virtual", "-c", "x"]) == 1
    assert "--observe must be within" in capsys.readouterr().err


def test_bus_that_cannot_be_opened_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["conformance", "--serial", "/nonexistent/tty-for-conformance"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lowerbase conformance: error: cannot open")


# -- the deliberate defects, on the simulated clock ------------------------------------------------


def test_defect_specs_parse_and_unknown_ones_are_refused() -> None:
    assert str(parse_fault("defect:no-watchdog")) == "defect:no-watchdog"
    with pytest.raises(ConfigError, match="unknown defect"):
        parse_fault("defect:nonsense")
    with pytest.raises(ConfigError, match="needs an argument"):
        parse_fault("defect")


def _counters(rig: SimRig, name: str) -> list[int]:
    return [int(f.values["Counter"]) for f in rig.frames(name)]


def test_defect_counter_stuck_and_bms_counters_advance() -> None:
    from lowerbase.bms.adapter import McuBmsAdapter

    def rig_with_bms(*faults: str) -> SimRig:
        profile = SimRig().profile
        return SimRig(profile, faults=faults,
                      bms=McuBmsAdapter.from_battery_table(profile.battery, soc=80))

    good = rig_with_bms()
    good.run(4.5)
    for name in ("Heartbeat", "ImuGyro", "BmsPack", "BmsLife"):
        counters = _counters(good, name)
        assert len(counters) >= 3 and counter_steps(counters)[1] == 0, name
    stuck = rig_with_bms("defect:counter-stuck")
    stuck.run(3.0)
    for name in ("Heartbeat", "ImuGyro", "BmsPack", "WheelFeedback"):
        assert set(_counters(stuck, name)) == {0}, name


def test_defect_slow_heartbeat() -> None:
    rig = SimRig(faults=["defect:slow-heartbeat"])
    rig.run(5.0)
    times = [f.t for f in rig.frames("Heartbeat")]
    assert cycle_stats(times)[0] == pytest.approx(1.0)


def test_defect_no_watchdog_keeps_the_last_command() -> None:
    rig = SimRig(faults=["defect:no-watchdog"])
    rig.enable()
    rig.drive(0.2, 0.0, 1.0)
    rig.run(2.0)  # four times commandTimeout without a MotionCommand
    assert rig.last("MotionState")["Linear"] == pytest.approx(0.2, abs=0.01)
    assert rig.last("SystemStatus")["WatchdogStop"] == 0


def test_defect_ignore_estop_and_param_no_nack() -> None:
    rig = SimRig(faults=["defect:ignore-estop", "defect:param-no-nack"])
    rig.enable()
    rig.run(0.1)
    rig.send("ControlCommand", Command="EStopSet")
    rig.run(0.2)
    assert rig.mcu.state == RobotState.ACTIVE
    rig.send("ParameterRequest", Index=10, Op=1, Value=6.0)  # joystickMaxLinear <= 3
    rig.run(0.02)
    reply = rig.last("ParameterResponse")
    assert (reply["Result"], reply["Value"]) == (0, 6.0)
    assert rig.mcu.chassis.joystick_max_linear == pytest.approx(0.6)  # acked, not applied


# -- against emulator processes -------------------------------------------------------------------


def _conformance(capsys: pytest.CaptureFixture[str], bus: list[str], *args: str
                 ) -> tuple[int, dict[str, str], str]:
    """Run ``lowerbase conformance`` in process: (exit code, id -> result, stdout)."""
    return run_conformance(capsys, ALL_IDS, *bus, *LOADED_HOST, *args)


def _failed(results: dict[str, str]) -> set[str]:
    return {cid for cid, result in results.items() if result in ("FAIL", "ERROR")}


def _emulator(lowerbase_proc: Any, bus: list[str], *faults: str) -> Any:
    proc = lowerbase_proc("emulate", *bus, *(f"--fault={f}" for f in faults))
    proc.wait_for("lower computer on")
    return proc


@pytest.mark.process
def test_emulator_passes_completely(lowerbase_proc: Any, udp_bus_config: dict[str, Any],
                                    tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bus = bus_cli_args(udp_bus_config)
    proc = _emulator(lowerbase_proc, bus)
    junit = tmp_path / "conformance.xml"
    code, results, out = _conformance(capsys, bus, "--junit", str(junit))
    assert code == 0, out
    assert list(results) == ALL_IDS
    assert set(results.values()) == {"PASS"}, out
    assert f"{len(ALL_IDS)} checks: {len(ALL_IDS)} passed, 0 failed" in out
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None
    assert suite.get("tests") == str(len(ALL_IDS))
    assert (suite.get("failures"), suite.get("errors"), suite.get("skipped")) == ("0", "0", "0")
    assert [c.get("name") for c in suite.iter("testcase")] == ALL_IDS
    code, err = proc.stop()
    assert code == 0, err
    assert "control_reboot 1" in err  # the suite rebooted it once ...
    assert "control_standby" in err  # ... and left it in standby


@pytest.mark.process
def test_counter_defect_fails_exactly_the_counter_checks(
        lowerbase_proc: Any, udp_bus_config: dict[str, Any],
        capsys: pytest.CaptureFixture[str]) -> None:
    bus = bus_cli_args(udp_bus_config)
    _emulator(lowerbase_proc, bus, "defect:counter-stuck")
    code, results, out = _conformance(capsys, bus, "--observe", "3")
    assert code == 1
    assert list(results) == ALL_IDS
    expected = {f"frame.{m.name}.counter" for m in periodic_lower_messages(CODEC)
                if m.has_counter}
    assert _failed(results) == expected, out
    assert "FAILED: " + ", ".join(sorted(expected)) in out


@pytest.mark.process
@pytest.mark.parametrize(("defect", "only", "expected"), [
    ("no-watchdog", "safety.enable,safety.watchdog,safety.estop,safety.standby",
     {"safety.watchdog"}),
    ("ignore-estop", "safety.enable,safety.estop,safety.standby,robust.unknown_id",
     {"safety.estop"}),
    ("param-no-nack", "param.*", {"param.out_of_range"}),
    ("slow-heartbeat", "link.*,frame.Heartbeat.*,frame.SystemStatus.cycle,safety.reboot",
     {"frame.Heartbeat.cycle"}),
])
def test_defect_fails_exactly_its_checks(
        lowerbase_proc: Any, udp_bus_config: dict[str, Any],
        capsys: pytest.CaptureFixture[str], defect: str, only: str, expected: set[str]) -> None:
    bus = bus_cli_args(udp_bus_config)
    _emulator(lowerbase_proc, bus, f"defect:{defect}")
    code, results, out = _conformance(capsys, bus, "--only", only, "--observe", "4")
    assert code == 1
    assert [c for c in ALL_IDS if c in results] == [c.id for c in select(registry(CODEC),
                                                                          [only])]
    assert _failed(results) == expected, out
    assert "SKIP" not in results.values(), out


@pytest.mark.process
def test_silent_lower_computer_fails_the_link_and_skips_the_rest(
        lowerbase_proc: Any, udp_bus_config: dict[str, Any],
        capsys: pytest.CaptureFixture[str]) -> None:
    bus = bus_cli_args(udp_bus_config)
    _emulator(lowerbase_proc, bus, "silence")
    code, results, out = _conformance(capsys, bus, "--only", "link.*,param.read,safety.*")
    assert code == 1
    assert _failed(results) == {"link.heartbeat"}, out
    assert {r for c, r in results.items() if c != "link.heartbeat"} == {"SKIP"}


def test_nothing_passed_on_a_silent_bus_is_a_failure(udp_bus_config: dict[str, Any],
                                                     tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Nobody on the bus and link.heartbeat not selected: every check is skipped, none
    failed, and still the run fails, with one line that says what to check."""
    bus = bus_cli_args(udp_bus_config)
    junit = tmp_path / "conformance.xml"
    code = main(["conformance", *bus, "--only", "frame.Heartbeat.*", "--junit", str(junit)])
    captured = capsys.readouterr()
    assert code == 1, captured.out
    assert "0 passed, 0 failed, 0 errors" in captured.out
    err = captured.err.strip().splitlines()
    assert err[-1].startswith("lowerbase conformance: error: nothing passed: no frame from a "
                              "lower computer"), err
    assert "239.74.163.99" in err[-1] and "is it running" in err[-1]
    assert junit.exists()  # written before the verdict


def test_a_run_of_skips_only_fails_and_says_so() -> None:
    """A lower computer answered but every selected check was skipped (e.g. --no-motion with
    only motion checks): not a pass either."""
    from lowerbase.conformance.core import Check, CheckResult, Report, nothing_passed
    from lowerbase.conformance.core import passed as pass_
    from lowerbase.conformance.core import skipped as skip

    check = Check("safety.watchdog", "the watchdog", lambda _: pass_())
    skips = Report((CheckResult(check, skip("needs motion (--no-motion)"), 0.0),), 1.0)
    assert skips.ok and "every check was skipped" in (nothing_passed(skips, "bus x") or "")
    silent = Report((CheckResult(check, skip("no lower computer"), 0.0),), 3.0, linked=False)
    assert "no frame from a lower computer on bus x" in (nothing_passed(silent, "bus x") or "")
    good = Report((CheckResult(check, pass_(), 0.0),), 1.0)
    assert nothing_passed(good, "bus x") is None


@pytest.mark.process
def test_serial_pty_run(lowerbase_proc: Any, tmp_path: Path,
                        capsys: pytest.CaptureFixture[str]) -> None:
    link = tmp_path / "chassis-tty"
    proc = lowerbase_proc("emulate", "--serial", f"pty:{link}")
    proc.wait_for("lower computer on")
    # the serial framing carries the suite: everything but the frame timing, which is the host's
    # here (a real-time emulator process: once a 0.5 s stall in CI, a 340 ms gap beside 12 busy
    # loops); the timing checks run in test_emulator_passes_completely (udp_multicast)
    frames = ",".join(f"frame.{m}.{c}" for m in ("Heartbeat", "WheelFeedback")
                      for c in ("present", "dlc", "range", "counter"))
    only = f"link.*,param.read,version.all,{frames},safety.enable,safety.watchdog,robust.bad_dlc"
    code, results, out = _conformance(capsys, ["--serial", str(link)], "--only", only,
                                      "--observe", "2")
    assert code == 0, out
    assert len(results) == len(select(registry(CODEC), [only]))
    assert set(results.values()) == {"PASS"}, out
    code, err = proc.stop()
    assert code == 0, err
