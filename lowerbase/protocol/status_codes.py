"""Bit meanings of the 64-bit StatusCode (std_msgs/UInt64 on status_code).

The table here is the one description; docs/status-codes.md is generated from it
(``python -m lowerbase.protocol.status_codes docs/status-codes.md``). A bit is set while its
condition holds; latched bits (marked) stay set until ControlCommand FaultClear finds the
condition gone (e-stop: until EStopRelease).
"""

from __future__ import annotations

import enum
import sys
from pathlib import Path


class StatusBit(enum.IntFlag):
    """StatusCode bits. 0 means no exception."""

    ESTOP_BUTTON = 1 << 0
    ESTOP_COMMAND = 1 << 1
    WATCHDOG_STOP = 1 << 2
    COMMAND_REJECTED = 1 << 3
    COMMAND_IN_STANDBY = 1 << 4
    LEFT_MOTOR_FAULT = 1 << 5
    RIGHT_MOTOR_FAULT = 1 << 6
    LEFT_OVER_CURRENT = 1 << 7
    RIGHT_OVER_CURRENT = 1 << 8
    LEFT_MOTOR_STALLED = 1 << 9
    RIGHT_MOTOR_STALLED = 1 << 10
    LEFT_ENCODER_FAULT = 1 << 11
    RIGHT_ENCODER_FAULT = 1 << 12
    IMU_FAULT = 1 << 13
    BMS_LINK_LOST = 1 << 14
    LOW_BATTERY = 1 << 15
    CRITICAL_BATTERY = 1 << 16
    BMS_PROTECTION = 1 << 17
    DRIVER_OVER_TEMPERATURE = 1 << 18
    BATTERY_OVER_TEMPERATURE = 1 << 19
    PARAMETER_ERROR = 1 << 20
    PARAMETER_STORE_FAILED = 1 << 21
    SPEED_LIMITED = 1 << 22
    CHARGING = 1 << 23
    BUS_ERROR = 1 << 24


#: (bit, latched, description) for every StatusBit
DESCRIPTIONS: dict[StatusBit, tuple[bool, str]] = {
    StatusBit.ESTOP_BUTTON: (True, "Emergency-stop button pressed; motors braked, released by EStopRelease once the button is up."),
    StatusBit.ESTOP_COMMAND: (True, "Emergency stop set by ControlCommand EStopSet; released by EStopRelease."),
    StatusBit.WATCHDOG_STOP: (False, "No MotionCommand within commandTimeout while moving under CAN control: stopped (at linear/angularDecelLimit after Smoothed commands, at the motor's limit after Raw ones) and held braked. Clears on the next valid command."),
    StatusBit.COMMAND_REJECTED: (True, "A MotionCommand was rejected: NaN, infinite, outside the catalog range or not decodable. Cleared by FaultClear."),
    StatusBit.COMMAND_IN_STANDBY: (False, "MotionCommands arrive while the chassis is in standby (CAN control not enabled); they are ignored."),
    StatusBit.LEFT_MOTOR_FAULT: (True, "Left motor driver fault (stall or over-current persisted); motors stopped until FaultClear."),
    StatusBit.RIGHT_MOTOR_FAULT: (True, "Right motor driver fault; motors stopped until FaultClear."),
    StatusBit.LEFT_OVER_CURRENT: (False, "Left motor current above the over-current limit."),
    StatusBit.RIGHT_OVER_CURRENT: (False, "Right motor current above the over-current limit."),
    StatusBit.LEFT_MOTOR_STALLED: (False, "Left wheel commanded but not turning."),
    StatusBit.RIGHT_MOTOR_STALLED: (False, "Right wheel commanded but not turning."),
    StatusBit.LEFT_ENCODER_FAULT: (False, "Left encoder count frozen while the motor draws driving current."),
    StatusBit.RIGHT_ENCODER_FAULT: (False, "Right encoder count frozen while the motor draws driving current."),
    StatusBit.IMU_FAULT: (False, "IMU output frozen (identical samples) or not updating."),
    StatusBit.BMS_LINK_LOST: (False, "The BMS did not answer the lower computer's polls for 3 s."),
    StatusBit.LOW_BATTERY: (False, "State of charge below the low-battery threshold (profile [power] low_battery_soc)."),
    StatusBit.CRITICAL_BATTERY: (False, "State of charge below the critical threshold (profile [power] critical_battery_soc): send the robot to charge; the BMS opens its discharge switch soon (BMS_PROTECTION)."),
    StatusBit.BMS_PROTECTION: (False, "The BMS opened its discharge switch (a protection tripped): motors stopped."),
    StatusBit.DRIVER_OVER_TEMPERATURE: (False, "Motor driver temperature above its limit. Reserved: the emulator has no driver temperature model and never sets it."),
    StatusBit.BATTERY_OVER_TEMPERATURE: (False, "Battery temperature at or above the warning threshold (profile [power] battery_temp_warning), or a BMS over-temperature status bit."),
    StatusBit.PARAMETER_ERROR: (True, "The parameter file was missing values, corrupt or out of range at boot; defaults used for those."),
    StatusBit.PARAMETER_STORE_FAILED: (True, "Writing the parameter file failed; the previous file is intact."),
    StatusBit.SPEED_LIMITED: (False, "The last command was clipped to maxLinear, maxAngular or maxRPM."),
    StatusBit.CHARGING: (False, "A charger is connected and charging."),
    StatusBit.BUS_ERROR: (False, "Frames to the upper computer are being dropped (bus silence or transmit errors)."),
}

#: bits that stop the motors while set
STOPPING = (
    StatusBit.ESTOP_BUTTON | StatusBit.ESTOP_COMMAND | StatusBit.LEFT_MOTOR_FAULT
    | StatusBit.RIGHT_MOTOR_FAULT | StatusBit.BMS_PROTECTION
)
LATCHED = StatusBit(sum(b for b, (latched, _) in DESCRIPTIONS.items() if latched))


def describe(code: int) -> list[str]:
    """Names of the bits set in ``code`` (unknown bits as 'bit N')."""
    names = [b.name or str(b) for b in StatusBit if code & b]
    known = sum(StatusBit)
    names += [f"bit {i}" for i in range(64) if code & ~known & (1 << i)]
    return names


def render() -> str:
    lines = [
        "# StatusCode bits",
        "",
        "The 64-bit exception code of the StatusCode frame (0x080) and of the ROS topic",
        "`status_code` (std_msgs/UInt64). Generated from `lowerbase/protocol/status_codes.py`",
        "(`make docs`). 0 means no exception. Latched bits stay set until ControlCommand",
        "FaultClear finds the condition gone (e-stop bits: until EStopRelease).",
        "",
        "| bit | mask | name | latched | meaning |",
        "|---|---|---|---|---|",
    ]
    for bit in StatusBit:
        latched, text = DESCRIPTIONS[bit]
        lines.append(
            f"| {bit.value.bit_length() - 1} | 0x{bit.value:X} | {bit.name} | "
            f"{'yes' if latched else 'no'} | {text} |"
        )
    lines += ["", "Bits 25..63 are reserved and always 0."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # pragma: no cover - make docs
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else None
    if target is None:
        print(render(), end="")
    else:
        from lowerbase.files import write_atomic

        write_atomic(target, render())
        print(f"wrote {target}")
