"""A crash keeps the odometer: ``lowerbase emulate --params FILE`` killed with SIGKILL while
driving comes back with the distance driven, less at most one save period's worth."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from lowerbase.conformance.lower_client import LowerClient
from lowerbase.firmware_model.mcu import ODOMETER_SAVE_PERIOD
from lowerbase.transport import open_bus
from tests.conftest import bus_cli_args

pytestmark = pytest.mark.process

SPEED = 0.4  #: [m/s] commanded (Raw)
DISTANCE = 1.0  #: [m] driven before the kill (~2.5 s of real time)
#: [s] beyond the save period: the control period the save check waits for, the Odometer
#: frame's 100 ms cycle and a short catch-up burst of a loaded real-time loop
SLACK = 0.2


def _drive_until(client: LowerClient, distance: float, timeout: float) -> float:
    """Send MotionCommand at its 20 ms cycle until an Odometer frame reports ``distance``;
    return that frame's distance. Does not stop sending gracefully: the caller kills."""
    start = client.latest("Odometer")
    assert start is not None
    goal = start.values["Distance"] + distance
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        client.send("MotionCommand", Linear=SPEED, Angular=0.0, Mode="Raw")
        last = client.latest("Odometer")
        if last is not None and last.values["Distance"] >= goal:
            return float(last.values["Distance"])
        time.sleep(0.02)  # the command's cycle, not a wait for a condition
    raise AssertionError(f"odometer did not reach {goal:.3f} m within {timeout} s")


def test_sigkill_while_driving_keeps_the_odometer(
        lowerbase_proc: Any, udp_bus_config: dict[str, Any], tmp_path: Path) -> None:
    params = tmp_path / "chassis-params.json"
    args = ("emulate", "--no-bms", "--params", str(params), *bus_cli_args(udp_bus_config))
    first = lowerbase_proc(*args)
    assert "boot #1" in first.wait_for("lower computer on")
    bus = open_bus(udp_bus_config)
    client = LowerClient(bus)
    try:
        assert client.expect("SystemStatus", lambda v: v["RobotState"] == 1, timeout=10.0)
        assert client.expect("Odometer", timeout=5.0) is not None
        client.send("ControlCommand", Command="EnableCanControl")
        assert client.expect("SystemStatus", lambda v: v["RobotState"] == 2, timeout=5.0)
        t_drive = time.monotonic()
        seen = _drive_until(client, DISTANCE, timeout=20.0)
        first.popen.kill()  # SIGKILL while driving: no shutdown handler runs
        assert first.popen.wait(timeout=10.0) == -9
        last = client.latest("Odometer")
        assert last is not None
        before_kill = float(last.values["Distance"])  # <= the odometer at the kill
        assert before_kill >= seen >= DISTANCE
        fastest = max([SPEED] + [abs(f.values["Linear"])
                                 for f in client.frames("MotionState", t_drive)])

        t_restart = time.monotonic()
        second = lowerbase_proc(*args)
        assert "boot #2" in second.wait_for("lower computer on")  # the file was read
        hb = client.expect("Heartbeat", since=t_restart, timeout=10.0)
        assert hb is not None and hb.values["BootCounter"] == 2
        odo = client.expect("Odometer", since=t_restart, timeout=5.0)
        assert odo is not None
        kept = float(odo.values["Distance"])
        lost_at_most = fastest * (ODOMETER_SAVE_PERIOD + SLACK)
        assert before_kill - lost_at_most <= kept, (
            f"odometer {kept:.3f} m after the kill, {before_kill:.3f} m seen before it "
            f"(at most {lost_at_most:.3f} m may be lost)")
        # and nothing invented: at most what was driven by the kill (the frame seen last is
        # at most one Odometer cycle plus the kill's latency behind it)
        assert kept <= before_kill + fastest * 0.5
    finally:
        client.close()
        bus.shutdown()
    code, err = second.stop()
    assert code == 0, err
