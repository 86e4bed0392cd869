"""BMS readings <-> the five Bms* CAN frames of ``chassis.dbc``.

:func:`snapshot_to_frames` gives the signal dicts the lower computer sends (saturated to each
signal's catalog range, as firmware saturates); :class:`BmsFrameAccumulator` rebuilds the
woosh_msgs/Battery and woosh_msgs/BMS fields from decoded frames (the ROS driver's side).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from lowerbase.bms.snapshot import BmsSnapshot

#: the Bms* messages, in the order the lower computer sends them
BMS_FRAMES: tuple[str, ...] = ("BmsPack", "BmsCell", "BmsCapacity", "BmsStatus", "BmsLife")

FrameSignals = dict[str, float | int]


def _clamp(value: float, lo: float, hi: float) -> float:
    return min(max(value, lo), hi)


def snapshot_to_frames(
    snapshot: BmsSnapshot, counters: Mapping[str, int] | None = None
) -> list[tuple[str, FrameSignals]]:
    """(message name, signals) for the five Bms* frames; ``counters`` holds each frame's
    rolling counter (missing = 0; taken mod 16). Encodable with the strict codec."""
    counters = counters or {}

    def counter(name: str) -> int:
        return int(counters.get(name, 0)) % 16

    s = snapshot
    return [
        ("BmsPack", {
            "Voltage": _clamp(s.voltage, 0.0, 655.35),
            "Current": _clamp(s.current, -327.68, 327.67),
            # whole percent, truncated as BMS firmware does: 19.9 % is "19 %", below a 20 %
            # low-battery threshold like the lower computer's own comparison
            "Soc": math.floor(_clamp(s.soc, 0.0, 100.0)),
            "ChargeMode": int(s.charge_mode) & 1,
            "ChargeStatus": int(s.charge_status) & 1,
            "SwitchStatus": int(s.switch_status) & 3,
            "Submodule": int(s.submodule) & 15,
            "Counter": counter("BmsPack"),
        }),
        ("BmsCell", {
            "CellVoltageMax": _clamp(s.cell_voltage_max, 0.0, 65.535),
            "CellVoltageMin": _clamp(s.cell_voltage_min, 0.0, 65.535),
            "TempMax": _clamp(s.temp_max, -204.8, 204.7),
            "TempMin": _clamp(s.temp_min, -204.8, 204.7),
            "Counter": counter("BmsCell"),
        }),
        ("BmsCapacity", {
            "CapacityRemain": _clamp(s.capacity_remain, 0.0, 655.35),
            "CapacityFull": _clamp(s.capacity_full, 0.0, 655.35),
            "CapacityDesign": _clamp(s.capacity_design, 0.0, 655.35),
            "Counter": counter("BmsCapacity"),
        }),
        ("BmsStatus", {
            "Status": int(s.bms_status) & 0xFFFFFFFF,
            "ChargeCycle": int(_clamp(s.charge_cycle, 0, 65535)),
            "Counter": counter("BmsStatus"),
        }),
        ("BmsLife", {
            "TimeRemain": round(_clamp(s.time_remain, 0.0, 65535.0)),
            "BatteryCycle": int(_clamp(s.battery_cycle, 0, 65535)),
            "Counter": counter("BmsLife"),
        }),
    ]


def advance_counters(
    counters: Mapping[str, int], names: Iterable[str] = BMS_FRAMES
) -> dict[str, int]:
    """The counters after one frame of each of ``names`` was sent (+1 mod 16)."""
    out = dict(counters)
    for name in names:
        out[name] = (int(out.get(name, 0)) + 1) % 16
    return out


def frames_to_snapshot(frames: Mapping[str, Mapping[str, Any]]) -> BmsSnapshot:
    """A snapshot from the decoded signals of all five Bms* frames (by message name).

    Raises KeyError naming the first missing frame.
    """
    missing = [name for name in BMS_FRAMES if name not in frames]
    if missing:
        raise KeyError(f"missing Bms frames: {missing}")
    pack, cell, cap = frames["BmsPack"], frames["BmsCell"], frames["BmsCapacity"]
    status, life = frames["BmsStatus"], frames["BmsLife"]
    return BmsSnapshot(
        voltage=float(pack["Voltage"]),
        current=float(pack["Current"]),
        soc=float(pack["Soc"]),
        cell_voltage_max=float(cell["CellVoltageMax"]),
        cell_voltage_min=float(cell["CellVoltageMin"]),
        temp_max=float(cell["TempMax"]),
        temp_min=float(cell["TempMin"]),
        capacity_remain=float(cap["CapacityRemain"]),
        capacity_full=float(cap["CapacityFull"]),
        capacity_design=float(cap["CapacityDesign"]),
        bms_status=int(status["Status"]),
        charge_cycle=int(status["ChargeCycle"]),
        battery_cycle=int(life["BatteryCycle"]),
        time_remain=float(life["TimeRemain"]),
        switch_status=int(pack["SwitchStatus"]),
        charge_status=int(pack["ChargeStatus"]),
        charge_mode=int(pack["ChargeMode"]),
        submodule=int(pack["Submodule"]),
    )


def frames_to_battery_fields(frames: Mapping[str, Mapping[str, Any]]) -> dict[str, float | int]:
    """woosh_msgs/Battery fields (header excluded) from the five decoded Bms* frames."""
    return frames_to_snapshot(frames).battery_fields()


def frames_to_bms_fields(frames: Mapping[str, Mapping[str, Any]]) -> dict[str, float | int]:
    """woosh_msgs/BMS fields (header excluded) from the five decoded Bms* frames."""
    return frames_to_snapshot(frames).bms_fields()


class BmsFrameAccumulator:
    """Collects decoded Bms* frames as they arrive; complete once all five were seen.

    ``update`` ignores other messages, so a driver can feed it every decoded frame.
    """

    def __init__(self) -> None:
        self.frames: dict[str, dict[str, Any]] = {}
        self._fresh: set[str] = set()  #: the Bms* frames come since the last whole burst

    def update(self, name: str, signals: Mapping[str, Any]) -> bool:
        """Store one decoded frame; True if it was a Bms* frame."""
        if name not in BMS_FRAMES:
            return False
        self.frames[name] = dict(signals)
        self._fresh.add(name)
        return True

    def take_burst(self) -> bool:
        """True once each Bms* frame has come again since the last True: a whole burst (the
        five frames of one 1 Hz cycle), so that /battery goes out once a cycle and never from
        a cycle half received. A frame lost from a cycle makes it wait for the next."""
        if len(self._fresh) < len(BMS_FRAMES):
            return False
        self._fresh.clear()
        return True

    @property
    def complete(self) -> bool:
        return all(name in self.frames for name in BMS_FRAMES)

    def snapshot(self) -> BmsSnapshot | None:
        """The latest values, or None until every Bms* frame arrived once."""
        return frames_to_snapshot(self.frames) if self.complete else None

    def battery_fields(self) -> dict[str, float | int] | None:
        snap = self.snapshot()
        return None if snap is None else snap.battery_fields()

    def bms_fields(self) -> dict[str, float | int] | None:
        snap = self.snapshot()
        return None if snap is None else snap.bms_fields()

    def clear(self) -> None:
        self.frames.clear()
        self._fresh.clear()
