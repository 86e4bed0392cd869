"""The Mcu's sending side: the periodic frames at their cycle times (built from the state, a
rolling Counter each) and the fault hooks on the way out (silence, drop, corrupt, delay).
Mixed into :class:`.mcu.Mcu`."""

from __future__ import annotations

import heapq
import math
from typing import Any

from lowerbase.firmware_model.mcu_defs import (
    BMS_LINK_TIMEOUT,
    ESTOP_BITS,
    PROTOCOL_VERSION,
    SB,
    SHARED_COUNTER,
    STOPPING,
    McuParts,
    RobotState,
    _clip,
)
from lowerbase.protocol.codec import MessageCodec


class McuFrames(McuParts):
    def _cycle(self, name: str) -> float:
        return self.codec.message(name).cycle_time or 0.0

    def _emit_due(self, now: float) -> None:
        if now + 1e-9 < self._next_any_due:
            return
        for i, msg in enumerate(self._periodic):
            due = self._due[i]
            if now + 1e-9 < due:
                continue
            # keep the period; after a stall, skip the missed slots instead of bursting
            period = msg.cycle_time or 0.0
            if msg.name == "Heartbeat" and self._active("defect", "slow-heartbeat"):
                period *= 2  # defect hook (conformance)
            missed = max(0, math.floor((now - due) / period)) if period else 0
            self._due[i] = due + (missed + 1) * period
            rows = self._build(msg)
            if msg.name in SHARED_COUNTER and rows and msg.has_counter:
                counter = self._counters[msg.name]  # one counter for all rows of a cycle
                self._advance_counter(msg.name)
                for values in rows:
                    values["Counter"] = counter
            for values in rows:
                self._emit(msg.name, values)
        self._next_any_due = min(self._due)

    def _build(self, msg: MessageCodec) -> list[dict[str, Any]]:
        name = msg.name
        if name == "WheelFeedback":
            rows = []
            for wheel, side in ((0, "left"), (1, "right")):  # multiplexed: Left*/Right*
                motor, enc, s = self._motors[side], self._encoders[side], side.title()
                rows.append({
                    f"{s}Count": enc.count,
                    f"{s}Velocity": _clip(self.wheel_velocity(side), msg, f"{s}Velocity"),
                    f"{s}Current": _clip(motor.current, msg, f"{s}Current"), "Wheel": wheel,
                    f"{s}DriverStatus": motor.status_bits | enc.status_bits})
            return rows
        if name == "MotionState":
            v, w = self._measured_twist()
            return [{"Linear": _clip(v, msg, "Linear"), "Angular": _clip(w, msg, "Angular")}]
        if name == "Odometer":
            return [{"Distance": _clip(self.odometer, msg, "Distance")}]
        if name in ("ImuGyro", "ImuAccel"):
            xyz = self.imu_sample[0 if name == "ImuGyro" else 1]
            return [{axis: _clip(val, msg, axis) for axis, val in zip("XYZ", xyz, strict=True)}]
        if name == "StatusCode":
            return [{"Code": self.status}]
        if name == "SystemStatus":
            snap = self.bms_snapshot
            volts = snap.voltage if snap is not None else 0.0
            return [{
                "RobotState": int(self.state),
                "ControlMode": 1 if self.state == RobotState.ACTIVE else 0,
                "EStop": int(bool(self.status & ESTOP_BITS)),
                "WatchdogStop": int(self._watchdog),
                "Braking": int(self._watchdog or bool(self.status & STOPPING)),
                "Charging": int(bool(self.status & SB.CHARGING)),
                "BatteryVoltage": _clip(volts, msg, "BatteryVoltage")}]
        if name == "Heartbeat":
            return [{"Uptime": _clip(self.clock.now() - self.boot_time, msg, "Uptime"),
                     "BootCounter": self.boot_counter, "ProtocolVersion": PROTOCOL_VERSION,
                     "Overruns": getattr(self.clock, "overruns", 0) % 16}]
        if name == "LedState":
            return [{"Strip": strip, "Submodule": sub, **led}
                    for (strip, sub), led in sorted(self.leds.items())]
        if name.startswith("Bms"):
            if self.bms is None or self.bms_snapshot is None or self._bms_link_lost():
                return []
            values = dict(self.bms.frame(name, self.bms_snapshot))
            del values["Counter"]  # the MCU's rolling counter, set in _emit (was stuck at 0)
            return [values]
        raise KeyError(name)  # pragma: no cover - every periodic message is built above

    def _bms_link_lost(self) -> bool:
        return self.clock.now() - self._bms_last_answer > BMS_LINK_TIMEOUT

    def _emit(self, name: str, values: dict[str, Any]) -> None:
        msg = self.codec.message(name)
        if msg.has_counter and "Counter" not in values:
            values["Counter"] = self._counters[name]
            self._advance_counter(name)
        data = msg.encode(values)
        if not self.faults:  # the common case: straight out
            self.stats["tx_frames"] += 1
            self._send(msg.frame_id, data)
            return
        if self._active("silence"):
            self.stats["tx_silenced"] += 1
            return
        drop = self._active("drop")
        if drop and self._rng.random() < drop.value:
            self.stats["tx_dropped"] += 1
            return
        corrupt = self._active("corrupt")
        if corrupt and self._rng.random() < corrupt.value:
            data = data[:-1]  # a frame one byte short: the strict decoder refuses it
            self.stats["tx_corrupted"] += 1
        delay = self._active("delay")
        if delay and delay.value > 0:
            self._seq += 1
            heapq.heappush(self._delayed, (self.clock.now() + delay.value, self._seq,
                                           msg.frame_id, data))
            return
        self.stats["tx_frames"] += 1
        self._send(msg.frame_id, data)

    def _advance_counter(self, name: str) -> None:
        if self.faults and self._active("defect", "counter-stuck"):  # defect hook (conformance)
            return
        self._counters[name] = (self._counters[name] + 1) & 0xF

    def _release_delayed(self, now: float) -> None:
        while self._delayed and self._delayed[0][0] <= now + 1e-9:
            _, _, frame_id, data = heapq.heappop(self._delayed)
            self.stats["tx_frames"] += 1
            self._send(frame_id, data)

