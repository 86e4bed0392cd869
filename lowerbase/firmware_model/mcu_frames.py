"""The Mcu's sending side: the rows of the periodic frames (built from the state; the 10 and
20 ms frames have their own builders in fastloop.py, which sends them at their cycle times),
the frames sent on request, and the fault hooks on the way out (silence, drop, corrupt,
delay).
Mixed into :class:`.mcu.Mcu`."""

from __future__ import annotations

import heapq
from typing import Any

from lowerbase.firmware_model.mcu_defs import (
    BMS_LINK_TIMEOUT,
    ESTOP_BITS,
    PROTOCOL_VERSION,
    SB,
    STOPPING,
    McuParts,
    RobotState,
    _clip,
)
from lowerbase.protocol.codec import MessageCodec


class McuFrames(McuParts):
    def _cycle(self, name: str) -> float:
        return self.codec.message(name).cycle_time or 0.0

    def _build(self, msg: MessageCodec) -> list[dict[str, Any]]:
        """The rows of periodic message ``msg`` (WheelFeedback, MotionState and the IMU's have
        builders of their own in fastloop.LeanLoop)."""
        name = msg.name
        if name == "Odometer":
            return [{"Distance": _clip(self.odometer, msg, "Distance")}]
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
        self._send_out(msg.frame_id, msg.encode(values))

    def _send_out(self, frame_id: int, data: bytes) -> None:
        """Send a frame through the fault hooks (silence, drop, corrupt, delay), counted."""
        if not self.faults:  # the common case: straight out
            self.stats["tx_frames"] += 1
            self._send(frame_id, data)
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
                                           frame_id, data))
            return
        self.stats["tx_frames"] += 1
        self._send(frame_id, data)

    def _advance_counter(self, name: str) -> None:
        if self.faults and self._active("defect", "counter-stuck"):  # defect hook (conformance)
            return
        self._counters[name] = (self._counters[name] + 1) & 0xF

    def _release_delayed(self, now: float) -> None:
        while self._delayed and self._delayed[0][0] <= now + 1e-9:
            _, _, frame_id, data = heapq.heappop(self._delayed)
            self.stats["tx_frames"] += 1
            self._send(frame_id, data)

