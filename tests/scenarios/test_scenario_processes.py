"""Scenarios over processes: ``lowerbase emulate`` in a child, the driver core on a bus."""

from __future__ import annotations

import json
import math
import signal
import time
from pathlib import Path
from typing import Any

import can
import pytest

from lowerbase.cli import main
from lowerbase.scenarios.demo import run_over_bus
from lowerbase.scenarios.wheeled import scenario_from_dict
from tests.conftest import bus_cli_args

pytestmark = pytest.mark.process

SHORT = {
    "scenario": {"name": "short", "duration": 3.5},
    "timeline": [
        {"at": 1.0, "action": "twist", "linear": 0.5, "duration": 2.0},
        {"at": 2.0, "fault": "estop", "duration": 0.5},
    ],
    "expect": [
        {"kind": "link", "equals": "ready", "at": 1.0},
        {"kind": "moving", "during": [1.5, 2.0], "speed": 0.4},
        {"kind": "stopped", "after": 2.0, "within": 0.6},
        {"kind": "status", "bit": "ESTOP_BUTTON", "sometime": [2.0, 2.6]},
        {"kind": "pose", "estimate": "odom", "within": 0.05},
    ],
}


def test_a_scenario_over_processes(tmp_path: Path, udp_bus_config: dict[str, Any]) -> None:
    scenario = scenario_from_dict(SHORT)
    # a run on the wall clock: one the host held up says so (result.lag) and is tried again;
    # a run that failed on time fails the test at once
    for attempt in range(1, 4):
        workdir = tmp_path / f"try{attempt}"
        result = run_over_bus(scenario, workdir, bus_config=udp_bus_config)
        assert result.lag is not None
        if result.passed or not result.lag.lagged:
            break
    failed = [f"{e.title()}: {o.detail}" for e, o in result.outcomes if not o.passed]
    assert result.passed, (failed, result.lag.describe())
    assert all(o.status == "passed" for _, o in result.outcomes)  # the truth came back too
    assert math.isfinite(result.trace["truth_x"][-1])
    log = (workdir / "emulator.log").read_text()
    assert "faults: estop@2+0.5" in log and "stopped after" in log  # the child ended cleanly


def test_ctrl_c_stops_the_run_and_the_emulator(tmp_path: Path, lowerbase_proc: Any) -> None:
    path = tmp_path / "long.toml"
    path.write_text("[scenario]\nduration = 60\n", encoding="utf-8")
    out = tmp_path / "report"
    proc = lowerbase_proc("scenario", "run", str(path), "--processes", "--out", str(out))
    log, run_log = out / "emulator.log", out / "run.log"

    def running() -> bool:  # the driver has configured the lower computer: the run is on
        return run_log.exists() and "lower computer configured" in run_log.read_text()

    deadline = time.monotonic() + 120  # a bound, not a speed: a busy host starts slowly
    while time.monotonic() < deadline and not running():
        time.sleep(0.05)
    assert running(), proc.popen.poll()
    proc.popen.send_signal(signal.SIGINT)
    code, err = proc.wait(timeout=60)
    assert code == 130, err
    assert "stopped after" in log.read_text()  # the child was stopped, not orphaned
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["passed"] is False


def test_record_a_live_bus(tmp_path: Path, udp_bus_config: dict[str, Any],
                           lowerbase_proc: Any) -> None:
    emulator = lowerbase_proc("emulate", *bus_cli_args(udp_bus_config))
    emulator.wait_for("lower computer on")
    everything, heartbeats = tmp_path / "all.log", tmp_path / "hb.asc"
    args = [*bus_cli_args(udp_bus_config), "--duration", "1.2"]
    assert main(["record", str(everything), *args]) == 0
    assert main(["record", str(heartbeats), *args, "--only", "Heartbeat"]) == 0
    frames = list(can.LogReader(str(everything)))
    assert len(frames) > 300  # IMU alone is 2 x 100 frames/s
    ids = {m.arbitration_id for m in can.LogReader(str(heartbeats))}
    assert ids == {0x090}
    assert main(["record", str(tmp_path / "x.txt"), *args]) == 1
    assert main(["record", str(heartbeats), *args, "--only", "Nothing"]) == 1
