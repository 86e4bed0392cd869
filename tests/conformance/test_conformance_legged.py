"""``lowerbase conformance --robot legged``: the emulator passes every check on the simulated
clock, each injected defect fails exactly its own checks, and the command runs against a
``lowerbase emulate --robot legged`` process on the four leg buses."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from lowerbase.cli import main
from lowerbase.conformance import Status, select
from lowerbase.conformance.legged_context import LeggedSettings
from lowerbase.conformance.legged_frames import body_messages
from lowerbase.conformance.legged_link import SimLink
from lowerbase.conformance.legged_runner import legged_registry, run_legged_suite
from lowerbase.errors import ConfigError
from lowerbase.legged.lower import DEFECTS
from lowerbase.protocol.legged import LocomotionState, legged_codec
from tests.conformance.cli_results import run_conformance
from tests.conftest import LOADED_HOST, bus_cli_args

CODEC = legged_codec()
ALL_IDS = [c.id for c in legged_registry()]


def _run(*defects: str, **settings: Any) -> tuple[dict[str, Status], SimLink]:
    link = SimLink(defects=defects)
    report = run_legged_suite(link, legged_registry(), LeggedSettings(**settings))
    return {r.check.id: r.outcome.status for r in report.results}, link


def _failed(results: dict[str, Status]) -> set[str]:
    return {c for c, s in results.items() if s in (Status.FAIL, Status.ERROR)}


def test_registry_covers_legged_dbc() -> None:
    assert len(ALL_IDS) == len(set(ALL_IDS))
    # every frame the DBC says the lower computer sends (Body, Actuator)
    for msg in CODEC:
        if "Body" not in msg.senders and "Actuator" not in msg.senders:
            assert not any(i.startswith(f"frame.{msg.name}.") for i in ALL_IDS)
            continue
        for aspect in ("present", "dlc", "range"):
            assert f"frame.{msg.name}.{aspect}" in ALL_IDS
        assert (f"frame.{msg.name}.cycle" in ALL_IDS) == msg.is_periodic
        periodic_body = msg in body_messages(CODEC)
        assert (f"frame.{msg.name}.counter" in ALL_IDS) == (periodic_body and msg.has_counter)
    assert "frame.LocomotionRequest.present" not in ALL_IDS  # the upper side sends it


def test_the_emulator_passes_every_check_and_is_left_comm_disabled() -> None:
    results, link = _run(zero_position=True)
    assert list(results) == ALL_IDS
    assert set(results.values()) == {Status.PASS}, _failed(results)
    assert link.lower.body.state is LocomotionState.COMM_DISABLED
    assert link.lower.stats["rx_actuator_command_refused"] == 5  # actuator.refused_...
    hip = link.lower.body.actuators[0]
    assert hip.zero_offset == pytest.approx(hip.position, abs=0.01)  # really re-zeroed


def test_without_zero_position_and_motion_those_checks_skip() -> None:
    results, link = _run(motion=False)
    skipped = {c for c, s in results.items() if s is Status.SKIP}
    assert skipped == {"actuator.zero_position", "body.stand", "body.velocity",
                       "body.velocity_timeout", "body.sit"}
    assert _failed(results) == set()
    assert link.lower.body.actuators[0].zero_offset == 0.0


@pytest.mark.parametrize(("defect", "expected"), [
    ("no-velocity-timeout", {"body.velocity_timeout"}),
    ("slow-status", {"frame.LocomotionStatus.cycle"}),
    ("obey-outside-test-mode", {"actuator.refused_outside_test_mode"}),
    ("no-exit-frames", {"actuator.exit_motor_mode"}),
])
def test_each_defect_fails_exactly_its_checks(defect: str, expected: set[str]) -> None:
    results, _ = _run(defect)
    assert list(results) == ALL_IDS
    assert _failed(results) == expected
    assert {c for c, s in results.items() if s is Status.SKIP} == {"actuator.zero_position"}


class StalledLink(SimLink):
    """The emulator's process descheduled for ``stall`` s (no step, no frame, the clock goes
    on), 0.3 s after the last BodyVelocityCommand: a loaded host."""

    def __init__(self, stall: float, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.stall, self.stalled = stall, False
        self.last_velocity: float | None = None

    def send(self, bus: int, frame_id: int, data: bytes) -> None:
        if frame_id == CODEC.message("BodyVelocityCommand").frame_id:
            self.last_velocity = self.clock.now()
        super().send(bus, frame_id, data)

    def wait(self, seconds: float) -> None:
        end = self.clock.now() + seconds - 1e-9
        while self.clock.now() < end:
            if (not self.stalled and self.last_velocity is not None
                    and self.clock.now() - self.last_velocity >= 0.3):
                self.stalled = True
                self.clock.advance(self.stall)
                continue
            self.lower.step()
            self.clock.advance(self.lower.dt)


@pytest.mark.parametrize("defects", [(), ("no-velocity-timeout",)])
def test_velocity_timeout_allows_a_measured_stall_only(defects: tuple[str, ...]) -> None:
    """A host stall between the last command and the stop is measured from the silent frames
    and allowed; a chassis that never stops still fails."""
    link = StalledLink(0.7, defects=defects)
    checks = select(legged_registry(), ["locomotion.*,body.stand,body.velocity*"])
    report = run_legged_suite(link, checks, LeggedSettings())
    outcome = {r.check.id: r.outcome for r in report.results}["body.velocity_timeout"]
    assert link.stalled
    if defects:
        assert outcome.status is Status.FAIL, outcome.detail
    else:
        assert outcome.status is Status.PASS, outcome.detail
        assert "0.7" in outcome.detail and "stall" in outcome.detail


def test_every_defect_is_tested_and_unknown_ones_are_refused() -> None:
    assert set(DEFECTS) == {"no-velocity-timeout", "slow-status", "obey-outside-test-mode",
                            "no-exit-frames"}
    with pytest.raises(ConfigError, match="unknown legged defect"):
        SimLink(defects=("nonsense",))


def test_no_bms_skips_the_bms_frames_only() -> None:
    link = SimLink(bms=False)
    checks = select(legged_registry(), ["link.*,locomotion.*,frame.*"])
    report = run_legged_suite(link, checks, LeggedSettings())
    skipped = {r.check.id for r in report.results if r.outcome.status is Status.SKIP}
    assert skipped == {c.id for c in checks if c.id.startswith("frame.Bms")}
    assert report.ok


def test_a_silent_bus_fails_the_link_and_skips_the_rest() -> None:
    class Silent(SimLink):
        def _from_lower(self, bus: int, frame_id: int, data: bytes) -> None:
            pass

    link = Silent()
    report = run_legged_suite(link, select(legged_registry(), ["link.*,locomotion.*"]),
                              LeggedSettings())
    assert report.failed_ids() == {"link.heartbeat"}
    assert {r.outcome.status for r in report.results[1:]} == {Status.SKIP}
    assert link.now() == pytest.approx(LeggedSettings().link_timeout, abs=0.01)


# -- the command against emulator processes -------------------------------------------------------


def _conformance(capsys: pytest.CaptureFixture[str], bus: list[str], *args: str
                 ) -> tuple[int, dict[str, str], str]:
    return run_conformance(capsys, ALL_IDS, "--robot", "legged", *bus, *LOADED_HOST, *args)


@pytest.mark.process
def test_command_against_the_emulator_process(
        lowerbase_proc: Any, udp_bus_config: dict[str, Any], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    bus = bus_cli_args(udp_bus_config)
    proc = lowerbase_proc("emulate", "--robot", "legged", *bus)
    proc.wait_for("legged lower computer on")
    junit = tmp_path / "legged.xml"
    code, results, out = _conformance(capsys, bus, "--junit", str(junit))
    assert list(results) == ALL_IDS
    # the .cycle and .counter checks measure whether this host runs the 1 kHz emulator and the
    # suite's 24,000 frames/s in real time (on a loaded 2-core machine it may not: a late loop
    # skips periods, so cycles stretch and counters jump; benchmarks/bench_legged.py measures
    # it); on the simulated clock they pass exactly (tests above)
    cycles = {c for c in ALL_IDS if c.endswith((".cycle", ".counter"))}
    failed = {c for c, r in results.items() if r == "FAIL"}
    assert failed <= cycles, out
    assert (code == 0) == (not failed)
    assert {c for c, r in results.items() if r == "SKIP"} == {"actuator.zero_position"}, out
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("tests") == str(len(ALL_IDS))
    assert suite.get("failures") == str(len(failed)) and suite.get("skipped") == "1"
    code, err = proc.stop()
    assert code == 0, err
    assert "in state COMM_DISABLED" in err and "rx_actuator_command_refused 5" in err


@pytest.mark.process
def test_command_finds_a_defect_of_the_emulator_process(
        lowerbase_proc: Any, udp_bus_config: dict[str, Any],
        capsys: pytest.CaptureFixture[str]) -> None:
    bus = bus_cli_args(udp_bus_config)
    proc = lowerbase_proc("emulate", "--robot", "legged", *bus,
                          "--fault", "defect:obey-outside-test-mode")
    proc.wait_for("legged lower computer on")
    only = "link.*,locomotion.*,actuator.*"
    code, results, out = _conformance(capsys, bus, "--only", only, "--no-motion")
    assert code == 1
    assert {c for c, r in results.items() if r == "FAIL"} == \
        {"actuator.refused_outside_test_mode"}, out
    assert "FAILED: actuator.refused_outside_test_mode" in out


def test_command_errors_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["conformance", "--robot", "legged", "--serial", "/dev/null"]) == 1
    assert main(["conformance", "--robot", "legged", "--only", "nothing.*"]) == 1
    err = capsys.readouterr().err
    assert "not --serial" in err and "no check matches" in err
    assert "Traceback" not in err
    assert main(["emulate", "--robot", "legged", "--fault", "stall:left"]) == 1
    assert "only --fault defect:NAME" in capsys.readouterr().err
