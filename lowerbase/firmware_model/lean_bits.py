"""The status-word bits of the lean control period, as plain module-level ints: shared by the
Python loop (fastloop.py) and the compiled one (lean_kernel.py, whose numba functions read
them as globals frozen at compile time)."""

from __future__ import annotations

from lowerbase.protocol.status_codes import StatusBit

_B = {b.name: int(b) for b in StatusBit}
ESTOP_COMMAND = _B["ESTOP_COMMAND"]
WATCHDOG_STOP = _B["WATCHDOG_STOP"]
COMMAND_IN_STANDBY = _B["COMMAND_IN_STANDBY"]
SPEED_LIMITED = _B["SPEED_LIMITED"]
IMU_FAULT = _B["IMU_FAULT"]
BMS_LINK_LOST = _B["BMS_LINK_LOST"]
ESTOP_BUTTON = _B["ESTOP_BUTTON"]
ESTOP_BITS = ESTOP_BUTTON | ESTOP_COMMAND
BMS_PROTECTION = _B["BMS_PROTECTION"]
#: per side: over-current, stalled, motor fault, encoder fault
L_OVER, L_STALL, L_FAULT, L_ENC = (_B[f"LEFT_{w}"] for w in (
    "OVER_CURRENT", "MOTOR_STALLED", "MOTOR_FAULT", "ENCODER_FAULT"))
R_OVER, R_STALL, R_FAULT, R_ENC = (_B[f"RIGHT_{w}"] for w in (
    "OVER_CURRENT", "MOTOR_STALLED", "MOTOR_FAULT", "ENCODER_FAULT"))
SIDE_BITS = ((L_OVER, L_STALL, L_FAULT, L_ENC), (R_OVER, R_STALL, R_FAULT, R_ENC))
