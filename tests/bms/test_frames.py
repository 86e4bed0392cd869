"""Bms* CAN frames carry the register values; the accumulator rebuilds the ROS fields."""

from __future__ import annotations

import pytest

from lowerbase.bms.frames import (
    BMS_FRAMES,
    BmsFrameAccumulator,
    advance_counters,
    frames_to_battery_fields,
    frames_to_bms_fields,
    frames_to_snapshot,
    snapshot_to_frames,
)
from lowerbase.bms.link import InProcessBmsLink
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.registers import INPUT_REGISTERS
from lowerbase.bms.snapshot import BmsSnapshot
from lowerbase.protocol.codec import default_codec

BATTERY_MSG_FIELDS = {
    "submodule", "batteryPercentage", "chargeMode", "chargeStatus", "batteryVoltage",
    "batteryCurrent", "timeRemain", "tempMax", "tempMin", "capacityRemain", "capacityFull",
    "capacityDesign", "chargeCycle", "batteryCycle", "cellVoltageMax", "cellVoltageMin",
    "bmsStatus",
}
BMS_MSG_FIELDS = {
    "BMSStatus", "current", "voltageMax", "voltageMin", "voltageTotal", "temperatureMax",
    "temperatureMin", "chargeCycle", "capacityResidue", "capacityTotal", "switchStatus",
}


def _over_the_wire(snap: BmsSnapshot, counters: dict[str, int]) -> dict[str, dict]:
    codec = default_codec()
    decoded = {}
    for name, signals in snapshot_to_frames(snap, counters):
        data = codec.encode(name, signals)
        got_name, values = codec.decode(codec.message(name).frame_id, data)
        assert got_name == name
        decoded[name] = values
    return decoded


def _register_snapshot(soc: float, load: float, charger: bool = False) -> BmsSnapshot:
    pack = BatteryPack(soc=soc)
    if charger:
        pack.connect_charger()
    pack.step(30.0, load)
    snap = InProcessBmsLink(pack).poll()
    assert snap is not None
    return snap


@pytest.mark.parametrize(
    ("soc", "load", "charger"), [(80, 25, False), (20, 0, True), (3, 60, False)]
)
def test_frames_carry_the_register_values(soc: float, load: float, charger: bool) -> None:
    snap = _register_snapshot(soc, load, charger)
    decoded = _over_the_wire(snap, {name: 5 for name in BMS_FRAMES})
    assert set(decoded) == set(BMS_FRAMES)
    assert all(values["Counter"] == 5 for values in decoded.values())
    back = frames_to_snapshot(decoded)
    # frames are at least as fine as the registers, except SOC (whole percent, truncated)
    for reg in INPUT_REGISTERS:
        if reg.name == "soc":
            assert 0 <= snap.soc - back.soc < 1.0
            continue
        tol = reg.scale / 2 + 1e-9
        assert getattr(back, reg.name) == pytest.approx(getattr(snap, reg.name), abs=tol), reg.name


def test_ros_fields_complete_and_consistent() -> None:
    snap = _register_snapshot(55, 10)
    decoded = _over_the_wire(snap, {})
    battery = frames_to_battery_fields(decoded)
    bms = frames_to_bms_fields(decoded)
    assert set(battery) == BATTERY_MSG_FIELDS
    assert set(bms) == BMS_MSG_FIELDS
    assert battery["batteryVoltage"] == bms["voltageTotal"] == pytest.approx(snap.voltage)
    assert battery["batteryCurrent"] == pytest.approx(snap.current) and snap.current < 0
    assert battery["batteryPercentage"] == int(snap.soc)  # truncated
    assert isinstance(battery["tempMax"], int)
    assert bms["switchStatus"] == 3


def test_accumulator_waits_for_all_five() -> None:
    acc = BmsFrameAccumulator()
    decoded = _over_the_wire(_register_snapshot(70, 5), {})
    assert not acc.update("MotorFeedback", {"x": 1})
    for name in BMS_FRAMES[:-1]:
        assert acc.update(name, decoded[name])
        assert acc.snapshot() is None and acc.battery_fields() is None
    acc.update(BMS_FRAMES[-1], decoded[BMS_FRAMES[-1]])
    assert acc.complete
    assert acc.battery_fields() == frames_to_battery_fields(decoded)
    assert acc.bms_fields() == frames_to_bms_fields(decoded)


def test_counters_roll_mod_16() -> None:
    c: dict[str, int] = {}
    for _ in range(17):
        c = advance_counters(c)
    assert c == {name: 1 for name in BMS_FRAMES}


def test_out_of_range_values_saturate() -> None:
    snap = BmsSnapshot(
        voltage=700.0, current=-400.0, soc=120.0, cell_voltage_max=3.6, cell_voltage_min=3.5,
        temp_max=250.0, temp_min=-250.0, capacity_remain=10.0, capacity_full=10.0,
        capacity_design=10.0, bms_status=0, charge_cycle=70000, battery_cycle=3000,
        time_remain=1e6, switch_status=3, charge_status=0, charge_mode=0, submodule=0,
    )
    decoded = _over_the_wire(snap, {})
    assert decoded["BmsPack"]["Soc"] == 100 and decoded["BmsLife"]["TimeRemain"] == 65535


def test_mcu_adapter() -> None:
    from lowerbase.bms.adapter import McuBmsAdapter
    from lowerbase.bms.device import BmsDevice
    from lowerbase.protocol.status_codes import StatusBit

    adapter = McuBmsAdapter(BmsDevice(BatteryPack(soc=4.0)))
    adapter.step(1.0, 10.0)
    snap = adapter.poll()
    assert snap is not None
    bits = adapter.status_bits(snap)
    assert bits & StatusBit.LOW_BATTERY and bits & StatusBit.CRITICAL_BATTERY
    assert not bits & StatusBit.BMS_PROTECTION
    for _ in range(3600):
        adapter.step(1.0, 40.0)
    snap = adapter.poll()
    assert snap is not None and adapter.status_bits(snap) & StatusBit.BMS_PROTECTION
    codec = default_codec()
    for name in BMS_FRAMES:
        codec.encode(name, adapter.frame(name, snap))
    with pytest.raises(KeyError):
        adapter.frame("Heartbeat", snap)


def test_a_burst_is_taken_once_whole_and_waits_for_a_lost_frame() -> None:
    acc = BmsFrameAccumulator()
    decoded = _over_the_wire(_register_snapshot(70, 5), {})
    taken = []
    for name in BMS_FRAMES * 2:  # two whole cycles
        acc.update(name, decoded[name])
        taken.append(acc.take_burst())
    assert taken == [False] * 4 + [True] + [False] * 4 + [True]
    for name in BMS_FRAMES[:-1]:  # a cycle whose BmsLife is lost: nothing yet
        acc.update(name, decoded[name])
        assert not acc.take_burst()
    for name in BMS_FRAMES:  # the next cycle: once, at its end
        acc.update(name, decoded[name])
        assert acc.take_burst() == (name == BMS_FRAMES[-1])
