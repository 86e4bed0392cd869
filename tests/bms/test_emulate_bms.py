"""The lower computer's BMS: its own pack, served over Modbus, or an external BMS polled."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.bms.link import ModbusTcpBmsLink
from lowerbase.conformance.lower_client import LowerClient
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.sim import SimRig
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.transport import open_bus
from tests.conftest import bus_cli_args, free_tcp_port


def test_silent_bms_sets_link_lost_and_bms_frames_stop() -> None:
    p = load_profile()
    rig = SimRig(p, bms=McuBmsAdapter.from_battery_table(p.battery, soc=60.0),
                 faults=["bms-silence@2"])
    rig.run(2.0)
    pack = rig.last("BmsPack")
    assert pack["Soc"] == 60
    assert not rig.status() & StatusBit.BMS_LINK_LOST
    rig.run(4.0)
    assert rig.status() & StatusBit.BMS_LINK_LOST
    assert not rig.frames("BmsPack", since=rig.now - 1.5)


def test_battery_drains_with_the_motors_load() -> None:
    p = load_profile()
    adapter = McuBmsAdapter.from_battery_table(p.battery, soc=50.0)
    rig = SimRig(p, bms=adapter)
    rig.enable()
    rig.run(5.0)
    idle = -rig.last("BmsPack")["Current"]
    rig.drive(1.0, 0.0, 5.0)
    driving = max(-f.values["Current"] for f in rig.frames("BmsPack", since=rig.now - 4))
    assert driving > idle > 0  # discharging shows as negative current on the wire


@pytest.mark.process
def test_emulator_serves_its_bms_over_modbus_tcp(lowerbase_proc: Any,
                                                 udp_bus_config: dict[str, Any]) -> None:
    port = free_tcp_port()
    proc = lowerbase_proc("emulate", *bus_cli_args(udp_bus_config), "--soc", "55",
                          "--bms-tcp", f"127.0.0.1:{port}")
    proc.wait_for("BMS (unit 1) on Modbus TCP")
    bus = open_bus(udp_bus_config)
    client = LowerClient(bus)
    link = ModbusTcpBmsLink("127.0.0.1", port, timeout=1.0)
    try:
        snapshot = link.poll()
        assert snapshot is not None and snapshot.soc == pytest.approx(55.0, abs=0.2)
        frame = client.expect("BmsPack", timeout=5.0)
        capacity = client.expect("BmsCapacity", timeout=5.0)
        assert frame is not None and capacity is not None
        # the same pack behind the registers and the frames (read at different instants, so
        # compare what does not move within a second)
        assert frame.values["Soc"] == int(snapshot.soc)
        assert capacity.values["CapacityDesign"] == pytest.approx(snapshot.capacity_design)
        assert capacity.values["CapacityFull"] == pytest.approx(snapshot.capacity_full)
        assert frame.values["Voltage"] == pytest.approx(snapshot.voltage, abs=0.5)
    finally:
        link.close()
        client.close()
        bus.shutdown()
    assert proc.stop()[0] == 0


@pytest.mark.process
def test_emulator_polls_an_external_bms_and_notices_when_it_dies(
        lowerbase_proc: Any, udp_bus_config: dict[str, Any]) -> None:
    port = free_tcp_port()
    bms = lowerbase_proc("bms", "--tcp", f"127.0.0.1:{port}", "--soc", "42")
    bms.wait_for("Modbus TCP listening")
    emu = lowerbase_proc("emulate", *bus_cli_args(udp_bus_config), "--bms-external",
                         "--bms-tcp", f"127.0.0.1:{port}")
    emu.wait_for("lower computer on")
    bus = open_bus(udp_bus_config)
    client = LowerClient(bus)
    try:
        frame = client.expect("BmsPack", lambda v: v["Soc"] == 42, timeout=8.0)
        assert frame is not None, "the external BMS's SOC never reached the bus"
        assert bms.stop()[0] == 0
        lost = client.expect("StatusCode", lambda v: v["Code"] & StatusBit.BMS_LINK_LOST,
                             timeout=8.0)
        assert lost is not None
    finally:
        client.close()
        bus.shutdown()
    assert emu.stop()[0] == 0


def test_low_battery_threshold_comes_from_the_profile() -> None:
    p = load_profile()
    p = p.replace(power=dataclasses.replace(p.power, low_battery_soc=50.0))
    rig = SimRig(p, bms=McuBmsAdapter.from_profile(p, soc=45.0))
    rig.run(1.5)
    assert rig.status() & StatusBit.LOW_BATTERY
    default = load_profile()
    rig = SimRig(default, bms=McuBmsAdapter.from_profile(default, soc=45.0))
    rig.run(1.5)
    assert not rig.status() & StatusBit.LOW_BATTERY


def test_power_thresholds_are_validated() -> None:
    from lowerbase.errors import ConfigError
    from lowerbase.firmware_model.profile import profile_from_dict

    with pytest.raises(ConfigError, match="critical_battery_soc"):
        profile_from_dict({"power": {"low_battery_soc": 10, "critical_battery_soc": 15}})
