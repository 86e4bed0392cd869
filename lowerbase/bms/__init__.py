"""The battery pack and its BMS: model, Modbus device, pollers and CAN frame mapping.

Light imports only; pymodbus is imported by :mod:`lowerbase.bms.device` and
:mod:`lowerbase.bms.link` when a server or a Modbus client is made.
"""

from lowerbase.bms.config import (
    BatteryConfig,
    ProtectionConfig,
    ProtectionLimit,
    default_battery_config,
    load_battery_config,
)
from lowerbase.bms.ocv import Chemistry
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.snapshot import BmsSnapshot
from lowerbase.bms.status import BmsStatus, ChargeMode, ChargeStatus, SwitchStatus

__all__ = [
    "BatteryConfig",
    "BatteryPack",
    "BmsSnapshot",
    "BmsStatus",
    "ChargeMode",
    "ChargeStatus",
    "Chemistry",
    "ProtectionConfig",
    "ProtectionLimit",
    "SwitchStatus",
    "default_battery_config",
    "load_battery_config",
]
