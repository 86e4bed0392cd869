"""One reading of the BMS: every field of woosh_msgs/Battery and woosh_msgs/BMS, once.

Fields that the two messages share (e.g. ``batteryVoltage`` and ``voltageTotal``) are one field
here; :meth:`BmsSnapshot.battery_fields` and :meth:`BmsSnapshot.bms_fields` give the messages'
own field names and types.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

#: ``timeRemain`` when the pack is not discharging [min] (the wire's 0xFFFF)
TIME_REMAIN_NOT_DISCHARGING = 65535.0


@dataclass(frozen=True)
class BmsSnapshot:
    """Pack state as a BMS reports it. Current is positive while charging."""

    voltage: float  #: pack terminal voltage [V] (batteryVoltage, voltageTotal)
    current: float  #: pack current [A], + charging (batteryCurrent, current)
    soc: float  #: state of charge [%] (batteryPercentage)
    cell_voltage_max: float  #: highest cell [V] (cellVoltageMax, voltageMax)
    cell_voltage_min: float  #: lowest cell [V] (cellVoltageMin, voltageMin)
    temp_max: float  #: hottest sensor [degC] (tempMax, temperatureMax)
    temp_min: float  #: coldest sensor [degC] (tempMin, temperatureMin)
    capacity_remain: float  #: remaining capacity [Ah] (capacityRemain, capacityResidue)
    capacity_full: float  #: full-charge capacity [Ah] (capacityFull, capacityTotal)
    capacity_design: float  #: design capacity [Ah] (capacityDesign)
    bms_status: int  #: status word, see :class:`~lowerbase.bms.status.BmsStatus`
    charge_cycle: int  #: completed charge cycles (chargeCycle)
    battery_cycle: int  #: rated cycle life (batteryCycle)
    time_remain: float  #: time to empty at the recent average current [min] (timeRemain)
    switch_status: int  #: bit 0 discharge, bit 1 charge switch closed (switchStatus)
    charge_status: int  #: 0 discharge, 1 charging (chargeStatus)
    charge_mode: int  #: 0 manual, 1 automatic (chargeMode)
    submodule: int  #: battery submodule number (submodule)

    def battery_fields(self) -> dict[str, float | int]:
        """The data fields of woosh_msgs/Battery (header excluded), with the message's types."""
        return {
            "submodule": int(self.submodule),
            "batteryPercentage": round(min(max(self.soc, 0.0), 100.0)),
            "chargeMode": int(self.charge_mode),
            "chargeStatus": int(self.charge_status),
            "batteryVoltage": float(self.voltage),
            "batteryCurrent": float(self.current),
            "timeRemain": float(self.time_remain),
            "tempMax": round(min(max(self.temp_max, -128.0), 127.0)),
            "tempMin": round(min(max(self.temp_min, -128.0), 127.0)),
            "capacityRemain": float(self.capacity_remain),
            "capacityFull": float(self.capacity_full),
            "capacityDesign": float(self.capacity_design),
            "chargeCycle": int(self.charge_cycle),
            "batteryCycle": int(self.battery_cycle),
            "cellVoltageMax": float(self.cell_voltage_max),
            "cellVoltageMin": float(self.cell_voltage_min),
            "bmsStatus": int(self.bms_status),
        }

    def bms_fields(self) -> dict[str, float | int]:
        """The data fields of woosh_msgs/BMS (header excluded), with the message's types."""
        return {
            "BMSStatus": int(self.bms_status),
            "current": float(self.current),
            "voltageMax": float(self.cell_voltage_max),
            "voltageMin": float(self.cell_voltage_min),
            "voltageTotal": float(self.voltage),
            "temperatureMax": float(self.temp_max),
            "temperatureMin": float(self.temp_min),
            "chargeCycle": int(self.charge_cycle),
            "capacityResidue": float(self.capacity_remain),
            "capacityTotal": float(self.capacity_full),
            "switchStatus": int(self.switch_status),
        }


#: snapshot field names in declaration order
SNAPSHOT_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(BmsSnapshot))
