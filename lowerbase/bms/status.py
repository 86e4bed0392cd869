"""The BMS status word (``bmsStatus`` / ``BMSStatus``, CAN ``BmsStatus.Status``) and switch bits.

Bits 0-7 are protections: each one opens a MOSFET switch until it releases (with hysteresis).
Bits 8-15 are warnings (no switch action); bits 16-23 report the charging state. The rest of
the 32-bit word is reserved and always 0. ``docs/bms-modbus.md`` lists the same table,
generated from :data:`STATUS_DESCRIPTIONS`.
"""

from __future__ import annotations

from enum import IntEnum, IntFlag


class BmsStatus(IntFlag):
    """Bits of the 32-bit BMS status word."""

    NONE = 0
    # -- protections (open a switch) -------------------------------------------------------
    CELL_OVER_VOLTAGE = 1 << 0
    CELL_UNDER_VOLTAGE = 1 << 1
    CHARGE_OVER_CURRENT = 1 << 2
    DISCHARGE_OVER_CURRENT = 1 << 3
    CHARGE_OVER_TEMPERATURE = 1 << 4
    CHARGE_UNDER_TEMPERATURE = 1 << 5
    DISCHARGE_OVER_TEMPERATURE = 1 << 6
    DISCHARGE_UNDER_TEMPERATURE = 1 << 7
    # -- warnings ------------------------------------------------------------------------
    SOC_LOW = 1 << 8
    # -- state ---------------------------------------------------------------------------
    CHARGER_CONNECTED = 1 << 16
    CHARGING = 1 << 17
    FULLY_CHARGED = 1 << 18


#: every protection bit (a set one means a switch is held open)
PROTECTION_MASK = BmsStatus(0xFF)

#: one line per bit, in bit order (the documentation table is generated from this)
STATUS_DESCRIPTIONS: dict[BmsStatus, str] = {
    BmsStatus.CELL_OVER_VOLTAGE: "Highest cell above the over-voltage trip; charge switch open.",
    BmsStatus.CELL_UNDER_VOLTAGE: (
        "Lowest cell below the under-voltage trip; discharge switch open."
    ),
    BmsStatus.CHARGE_OVER_CURRENT: "Charge current above its trip; charge switch open.",
    BmsStatus.DISCHARGE_OVER_CURRENT: "Discharge current above its trip; discharge switch open.",
    BmsStatus.CHARGE_OVER_TEMPERATURE: "Too hot to charge; charge switch open.",
    BmsStatus.CHARGE_UNDER_TEMPERATURE: "Too cold to charge; charge switch open.",
    BmsStatus.DISCHARGE_OVER_TEMPERATURE: "Too hot to discharge; both switches open.",
    BmsStatus.DISCHARGE_UNDER_TEMPERATURE: "Too cold to discharge; discharge switch open.",
    BmsStatus.SOC_LOW: "State of charge below the low-SOC warning level (no switch action).",
    BmsStatus.CHARGER_CONNECTED: "A charger is connected.",
    BmsStatus.CHARGING: "Charge current is flowing (CC or CV phase).",
    BmsStatus.FULLY_CHARGED: "The last CC-CV charge terminated; SOC recalibrated to 100 %.",
}


class SwitchStatus(IntFlag):
    """``switchStatus``: the BMS MOSFET switches (a set bit means closed, i.e. conducting)."""

    NONE = 0
    DISCHARGE = 1 << 0
    CHARGE = 1 << 1


class ChargeMode(IntEnum):
    """``chargeMode`` (woosh_msgs/Battery): how the charger is connected."""

    MANUAL = 0  #: a charger plugged in by hand
    AUTO = 1  #: the robot docked on its charging station


class ChargeStatus(IntEnum):
    """``chargeStatus`` (woosh_msgs/Battery)."""

    DISCHARGE = 0
    CHARGING = 1


def describe_status(status: int) -> list[str]:
    """Names of the bits set in ``status`` (unknown bits as ``bitN``), in bit order."""
    names = []
    for bit in range(32):
        if status & (1 << bit):
            try:
                names.append(str(BmsStatus(1 << bit).name))
            except ValueError:
                names.append(f"bit{bit}")
    return names
