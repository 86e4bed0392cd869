"""``lowerbase emulate`` in its own process, a python-can client in this one."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from lowerbase.conformance.lower_client import LowerClient
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.transport import open_bus
from tests.conftest import bus_cli_args

pytestmark = pytest.mark.process


def _drive_and_check(client: LowerClient) -> None:
    assert client.expect("Heartbeat", timeout=10.0) is not None, "no Heartbeat"
    assert client.expect("SystemStatus", lambda v: v["RobotState"] == 1, timeout=5.0)
    client.send("ControlCommand", Command="EnableCanControl")
    assert client.expect("SystemStatus", lambda v: v["RobotState"] == 2, timeout=5.0)
    start = client.latest("WheelFeedback")
    assert start is not None
    end = time.monotonic() + 1.0
    while time.monotonic() < end:  # MotionCommand at its 20 ms cycle, as a driver sends it
        client.send("MotionCommand", Linear=0.3, Angular=0.0, Mode="Raw")
        time.sleep(0.02)
    moving = client.expect("MotionState", lambda v: v["Linear"] > 0.25, timeout=1.0,
                           since=end - 1.0)
    assert moving is not None
    counts = [f.values["LeftCount"] for f in client.frames("WheelFeedback", since=start.t)
              if f.values["Wheel"] == 0]
    assert counts[-1] > counts[0]
    # stop sending: the watchdog brakes within commandTimeout + the ramp
    stopped = client.expect(
        "StatusCode", lambda v: v["Code"] & StatusBit.WATCHDOG_STOP, timeout=2.0)
    assert stopped is not None
    assert client.stats["malformed"] == 0


def test_emulator_process_over_udp_multicast(lowerbase_proc: Any,
                                             udp_bus_config: dict[str, Any]) -> None:
    proc = lowerbase_proc("emulate", *bus_cli_args(udp_bus_config))
    proc.wait_for("lower computer on")
    bus = open_bus(udp_bus_config)
    client = LowerClient(bus)
    try:
        _drive_and_check(client)
    finally:
        client.close()
        bus.shutdown()
    code, err = proc.stop()
    assert code == 0, err
    assert "stopped after" in err


def test_emulator_process_over_serial_pty(lowerbase_proc: Any, tmp_path: Path) -> None:
    link = tmp_path / "chassis-tty"
    proc = lowerbase_proc("emulate", "--serial", f"pty:{link}")
    proc.wait_for("lower computer on")
    bus = open_bus(interface="lowerbase_serial", channel=str(link))
    client = LowerClient(bus)
    try:
        _drive_and_check(client)
        assert bus.deframer.stats.total_errors == 0  # type: ignore[attr-defined]
    finally:
        client.close()
        bus.shutdown()
    code, err = proc.stop()
    assert code == 0, err
    assert not link.exists()


def test_bad_interface_is_one_clear_line(lowerbase_proc: Any) -> None:
    proc = lowerbase_proc("emulate", "-i", "socketcan", "-c", "nosuchcan0")
    code, err = proc.wait(timeout=20)
    assert code == 1
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines[-1].startswith("lowerbase emulate: error: cannot open socketcan")
    assert "Traceback" not in err


def test_extended_and_remote_frames_are_not_catalog_frames(
        lowerbase_proc: Any, udp_bus_config: dict[str, Any]) -> None:
    """An extended frame with ID 0x10 is some other device's, not a ControlCommand Reboot."""
    import can

    proc = lowerbase_proc("emulate", *bus_cli_args(udp_bus_config))
    proc.wait_for("lower computer on")
    bus = open_bus(udp_bus_config)
    client = LowerClient(bus)
    try:
        first = client.expect("Heartbeat", timeout=10.0)
        assert first is not None
        boot = first.values["BootCounter"]
        bus.send(can.Message(arbitration_id=0x10, data=b"\x07", is_extended_id=True))
        bus.send(can.Message(arbitration_id=0x10, is_remote_frame=True, is_extended_id=False))
        later = client.expect("Heartbeat", lambda v: v["Uptime"] > 1.5, timeout=5.0)
        assert later is not None and later.values["BootCounter"] == boot
    finally:
        client.close()
        bus.shutdown()
    code, err = proc.stop()
    assert code == 0 and "rx_not_classic 2" in err
