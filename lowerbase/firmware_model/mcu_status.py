"""The Mcu's status word and BMS supervision: the load current, the pack step and poll, the
StatusCode bits from their causes and the state they force. Mixed into :class:`.mcu.Mcu`."""

from __future__ import annotations

from lowerbase.firmware_model.mcu_defs import (
    BMS_POLL_PERIOD,
    BMS_STEP,
    CARRIED,
    ENCODER_FAULT_TIME,
    IMU_FROZEN_SAMPLES,
    SB,
    STANDBY_HINT_TIME,
    McuParts,
    RobotState,
)


class McuStatus(McuParts):
    def load_current(self) -> float:
        """Battery current drawn by the motor drivers [A] (positive = discharge). The
        electronics (computers, sensors, LEDs) are the battery's ``idle_current_a``, counted
        by the pack model once."""
        total = self.profile.motor.idle_current * 2
        for motor in self._motors.values():
            # electrical power ~ torque current x motor speed share, at the pack voltage
            rpm_share = abs(motor.motor_rpm) / max(self.chassis.max_rpm, 1.0)
            total += abs(motor.current) * rpm_share
        return total

    def _update_bms(self, now: float, dt: float) -> None:
        if self.bms is None:
            return
        # the pack integrates charge exactly over a batch; stepping it every control period
        # would cost more than the whole control loop
        self._bms_charge += self.load_current() * dt
        self._bms_elapsed += dt
        if self._bms_elapsed >= BMS_STEP - 1e-9:
            self.bms.step(self._bms_elapsed, self._bms_charge / self._bms_elapsed)
            self._bms_charge = self._bms_elapsed = 0.0
        if now < self._bms_next_poll:
            return
        self._bms_next_poll += BMS_POLL_PERIOD
        snapshot = None if self._active("bms-silence") else self.bms.poll()
        if snapshot is not None:
            self.bms_snapshot = snapshot
            self._bms_bits = int(self.bms.status_bits(snapshot))
            self._bms_last_answer = now

    def _update_status(self, now: float) -> None:
        # event-latched bits carry over; the others are recomputed from their causes below
        s = self.status & CARRIED
        if self._active("estop"):
            s |= SB.ESTOP_BUTTON
        if self.estop_command:
            s |= SB.ESTOP_COMMAND
        if self._watchdog:
            s |= SB.WATCHDOG_STOP
        if now - self._standby_cmd_time < STANDBY_HINT_TIME:
            s |= SB.COMMAND_IN_STANDBY
        if self._speed_limited and self._last_cmd is not None:
            s |= SB.SPEED_LIMITED
        for side, prefix in (("left", "LEFT"), ("right", "RIGHT")):
            motor = self._motors[side]
            if motor.over_current:
                s |= getattr(SB, f"{prefix}_OVER_CURRENT")
            if motor.stalled:
                s |= getattr(SB, f"{prefix}_MOTOR_STALLED")
            if motor.over_current or motor.stalled:
                s |= getattr(SB, f"{prefix}_MOTOR_FAULT")
                self.motion_fault |= getattr(SB, f"{prefix}_MOTOR_FAULT")
            if self._enc_stuck[side] >= ENCODER_FAULT_TIME:
                s |= getattr(SB, f"{prefix}_ENCODER_FAULT")
        s |= self.motion_fault
        if self._imu_same >= IMU_FROZEN_SAMPLES:
            s |= SB.IMU_FAULT
        if self._active("silence") or self._active("drop") or self._active("corrupt"):
            s |= SB.BUS_ERROR
        s |= self._bms_status_bits()
        # the button e-stop is latched only while pressed; releasing needs EStopRelease too
        if s & SB.ESTOP_BUTTON:
            self.estop_command = True
        self.status = int(s)
        if self.state in (RobotState.ACTIVE, RobotState.EMERGENCY_STOP, RobotState.FAULT):
            if self.status & (SB.ESTOP_BUTTON | SB.ESTOP_COMMAND):
                self.state = RobotState.EMERGENCY_STOP
            elif self.motion_fault or self.status & SB.BMS_PROTECTION:
                self.state = RobotState.FAULT
            elif self.state != RobotState.ACTIVE:
                self.state = RobotState.STANDBY  # released: wait to be enabled again

    def _bms_status_bits(self) -> int:
        if self.bms is None:
            return 0
        return (SB.BMS_LINK_LOST if self._bms_link_lost() else 0) | self._bms_bits

