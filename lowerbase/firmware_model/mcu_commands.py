"""The Mcu's receiving side: frames from the upper computer (MotionCommand, ControlCommand,
LedCommand, ParameterRequest, VersionRequest) and their in-process equivalents
(``command``, ``control``, ``parameter``). Mixed into :class:`.mcu.Mcu`."""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

from lowerbase.errors import ConfigError, ProtocolError
from lowerbase.firmware_model import kinematics
from lowerbase.firmware_model.mcu_defs import (
    LATCHED,
    SB,
    VALID_LED_NORMAL,
    Command,
    McuParts,
    RobotState,
)
from lowerbase.firmware_model.parameters import SPECS, Result, check
from lowerbase.firmware_model.smoother import SmootherLimits

log = logging.getLogger("lowerbase.firmware_model.mcu")


class McuCommands(McuParts):
    def receive(self, frame_id: int, data: bytes) -> None:
        """Handle one frame from the bus. Bad frames are counted and dropped, never raised."""
        self.stats["rx_frames"] += 1
        if frame_id not in self.codec:
            self.stats["rx_unknown_id"] += 1
            return
        msg = self.codec.message(frame_id)
        if "Upper" not in msg.senders:
            self.stats["rx_ignored"] += 1  # our own frames echoed, or another lower computer
            return
        if self.state == RobotState.BOOT:
            self.stats["rx_during_boot"] += 1
            return
        try:
            values = msg.decode(data)
        except ProtocolError as exc:
            self.stats["rx_malformed"] += 1
            if msg.name == "MotionCommand":
                self.status |= SB.COMMAND_REJECTED
            log.debug("dropped %s: %s", msg.name, exc)
            return
        handler = getattr(self, f"_on_{msg.name}")
        handler(values)

    def command(self, linear: float, angular: float, smoothed: bool = False) -> bool:
        """In-process MotionCommand (what the frame does). False when rejected."""
        return self._motion(linear, angular, 1 if smoothed else 0)

    def _on_MotionCommand(self, v: dict[str, Any]) -> None:
        self._motion(float(v["Linear"]), float(v["Angular"]), int(v["Mode"]))

    def _motion(self, linear: float, angular: float, mode: int) -> bool:
        now = self.clock.now()
        if self.state != RobotState.ACTIVE:
            self._standby_cmd_time = now
            self.stats["rx_motion_ignored"] += 1
            return False
        key = (linear, angular, self.chassis)
        if linear and angular and key == self._limited_key:  # 0.0 and -0.0 compare equal
            lim = self._limited  # the same command again: limit_twist is a pure function
        else:
            lim = kinematics.limit_twist(linear, angular, self.chassis)
            self._limited_key, self._limited = key, lim
        if not lim.valid:
            self.status |= SB.COMMAND_REJECTED
            self.stats["rx_motion_rejected"] += 1
            return False
        self._speed_limited = lim.clipped
        self._last_cmd = (lim.v, lim.w, mode)
        self._last_cmd_time = now
        return True

    def _on_ControlCommand(self, v: dict[str, Any]) -> None:
        self.control(Command(int(v["Command"])))

    def control(self, cmd: Command) -> None:
        """ControlCommand, in process."""
        self.stats[f"control_{cmd.name.lower()}"] += 1
        if cmd == Command.ENABLE_CAN_CONTROL:
            if self.state == RobotState.STANDBY:
                self.state = RobotState.ACTIVE
                self._last_cmd = None
                self._last_cmd_time = self.clock.now()  # the watchdog starts now
        elif cmd == Command.STANDBY:
            if self.state == RobotState.ACTIVE:
                self.state = RobotState.STANDBY
        elif cmd == Command.ESTOP_SET:
            if not self._active("defect", "ignore-estop"):  # defect hook (conformance)
                self.estop_command = True
        elif cmd == Command.ESTOP_RELEASE:
            if self._active("estop"):
                return  # the button is still pressed
            self.estop_command = False
            self.status &= ~int(SB.ESTOP_BUTTON | SB.ESTOP_COMMAND)
            if self.state == RobotState.EMERGENCY_STOP:
                self.state = RobotState.STANDBY  # wait to be enabled again
        elif cmd == Command.FAULT_CLEAR:
            self._fault_clear()
        elif cmd == Command.ODOMETER_RESET:
            self.odometer = 0.0
            self._save_state()
        elif cmd == Command.REBOOT:
            self._save_state()
            self.power_on()

    def _fault_clear(self) -> None:
        keep = 0
        faults = (("left", SB.LEFT_MOTOR_FAULT), ("right", SB.RIGHT_MOTOR_FAULT))
        for side, bit in faults:
            motor = self._motors[side]
            cause = self._active("stall", side) or self._active("overcurrent", side)
            if cause:
                keep |= bit
            else:
                motor.clear_faults()
        self.motion_fault &= keep
        self.status &= ~LATCHED & ~(SB.ESTOP_BUTTON | SB.ESTOP_COMMAND)
        self.status |= keep

    def _on_LedCommand(self, v: dict[str, Any]) -> None:
        if v["Urgency"] not in (0, 0xFF) or v["Abnormal"] not in (0, 0xFF) or (
            v["Normal"] not in VALID_LED_NORMAL
        ):
            self.stats["rx_led_invalid"] += 1
            return
        subs = range(1, 9) if v["Submodule"] == 0 else (int(v["Submodule"]),)
        for sub in subs:
            self.leds[(int(v["Strip"]), sub)] = {
                k: int(v[k]) for k in ("Urgency", "Abnormal", "Normal", "Color")
            }

    def _on_ParameterRequest(self, v: dict[str, Any]) -> None:
        index, op = int(v["Index"]), int(v["Op"])
        result, value = self.parameter(index, float(v["Value"]) if op == 1 else None)
        self._emit("ParameterResponse", {"Index": index, "Op": op, "Result": int(result),
                                         "Value": value})

    def parameter(self, index: int, value: float | None = None) -> tuple[Result, float]:
        """Read (value None) or write one parameter; returns (result, value in force)."""
        spec = SPECS.get(index)
        if spec is None:
            return Result.UNKNOWN_INDEX, 0.0
        current = float(self.chassis.as_wire_dict()[spec.name])
        if value is None:
            return Result.ACK, current
        result = check(spec, value)
        if result == Result.OUT_OF_RANGE and self._active("defect", "param-no-nack"):
            return Result.ACK, value  # defect hook (conformance): acked, not applied
        if result != Result.ACK:
            return result, current
        if spec.only_at_rest and not self.at_rest():
            return Result.NOT_ALLOWED_NOW, current
        try:
            new = self.chassis.with_wire_value(spec.name, int(value) if spec.integer else value)
        except ConfigError:
            return Result.OUT_OF_RANGE, current  # breaks a relation (e.g. minSpeed < maxSpeed)
        old = self.chassis
        self.chassis = new
        self._save_state()
        if self.status & SB.PARAMETER_STORE_FAILED and self.store.path is not None:
            self.chassis = old  # not persisted: keep what the file says
            return Result.STORAGE_ERROR, current
        self._apply_chassis()
        return Result.ACK, float(self.chassis.as_wire_dict()[spec.name])

    def at_rest(self) -> bool:
        """Both wheels report 0 (WheelFeedback Velocity as the upper side decodes it)."""
        msg = self.codec.message("WheelFeedback")
        scale = msg.signal("LeftVelocity").scale
        return all(round(self.wheel_velocity(side) / scale) == 0 for side in ("left", "right"))

    def _apply_chassis(self) -> None:
        """New beliefs take effect; the hardware (motors' gears and wheels, encoders) stays."""
        for motor in self._motors.values():
            motor.geometry = replace(motor.geometry, max_rpm=self.chassis.max_rpm)
        self.smoother.limits = SmootherLimits.from_chassis(self.chassis)

    def _on_VersionRequest(self, v: dict[str, Any]) -> None:
        ident = self.profile.identity
        strings = {
            1: ident.hardware_version, 2: ident.software_version,
            3: ident.iap_software_version, 4: ident.movebase_type,
        }
        fields = strings if int(v["Field"]) == 0 else {int(v["Field"]): strings[int(v["Field"])]}
        for field, text in fields.items():
            raw = text.encode("ascii")
            chunks = [raw[i : i + 6] for i in range(0, len(raw), 6)] or [b""]
            for seq, chunk in enumerate(chunks):
                self._emit("VersionResponse", {
                    "Field": field, "Last": int(seq == len(chunks) - 1), "Sequence": seq,
                    "Text": int.from_bytes(chunk.ljust(6, b"\0"), "little")})

