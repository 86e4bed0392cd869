"""The legged robot's lower computer on its four CAN buses: the body controller, the 12
actuators' firmware, the battery's BMS and the body frames, on an injected clock.

Every 1 ms :meth:`LeggedLower.step`:

1. steps the body controller (:class:`~lowerbase.legged.body.Body`), the body temperature
   (:class:`~lowerbase.legged.thermal.BodyThermal`) and the pack (``lowerbase.bms``);
2. from COMM_ENABLED on (except IN_TEST_MODE) commands each actuator on its leg bus (bus k =
   leg ``LEGS[k]``, CAN IDs 1..3): the body controller's MIT command in motor mode, zero gains
   outside it; on entering MOTOR_COMMUTATION the enter-motor-mode frame instead, on leaving
   motor mode the exit frame. Each actuator answers each frame with ``MotorReply``: 3 commands
   and 3 replies per leg bus per ms;
3. sends the body frames that are due on bus 0 at their DBC cycle times (LocomotionStatus,
   Heartbeat, Base*, BodyTemperature, and the Bms* frames while the BMS answers).

From the upper side (:meth:`receive`, bus 0): ``LocomotionRequest`` (checked against the state
table, answered in LocomotionStatus) and ``BodyVelocityCommand`` (stale after the profile's
``command_timeout``: the gait keeps trotting on the spot). Actuator command frames from the
upper side are obeyed only in IN_TEST_MODE (and answered at once by the actuator); otherwise,
like anything malformed or unknown, they are counted in :attr:`stats` and dropped.

Faults the body controller latches besides the actuators' own: body over-temperature
(``thermal.body_fault_c``) and battery protection (the BMS opened its discharge switch, or the
SOC fell below ``power.critical_battery_soc``). MOTOR_READY clears them once the cause is gone.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import Counter
from collections.abc import Callable
from typing import Any

from lowerbase.bms.status import SwitchStatus
from lowerbase.clock import Clock
from lowerbase.errors import ConfigError, ProtocolError
from lowerbase.legged.actuator import Actuator
from lowerbase.legged.profile import LeggedProfile
from lowerbase.legged.thermal import BodyThermal, copper_loss, electrical_power
from lowerbase.protocol.codec import Codec
from lowerbase.protocol.legged import (
    BODY_BUS,
    COMMAND_MESSAGES,
    KD_MAX,
    KP_MAX,
    N_JOINTS,
    P_MAX,
    REPLY_ID,
    REPLY_PREFIX,
    T_MAX,
    V_MAX,
    Fault,
    LocomotionState,
    RequestResult,
    Special,
    joint_address,
    joint_index,
    legged_codec,
    parse_special,
    special_frame,
)

log = logging.getLogger(__name__)

S = LocomotionState
#: (bus, frame ID, payload) -> the wire
Send = Callable[[int, int, bytes], None]

DT = 0.001  #: [s] the control loop, = the actuator commands' DBC cycle time
PROTOCOL_VERSION = 1
BMS_POLL_PERIOD = 0.5  #: [s]
BMS_STEP = 0.1  #: [s] the pack is stepped with the mean load over this period
BMS_LINK_TIMEOUT = 3.0  #: [s] without an answer the Bms* frames stop
#: states in which the actuators are in motor mode (leaving them sends exit-motor-mode)
MOTOR_MODE_STATES = frozenset({S.MOTOR_COMMUTATION, S.MOTOR_ENABLED, S.IN_TEST_MODE,
                               S.STANDING_MODE, S.IN_CONTROL, S.SITDOWN_MODE})
#: states in which the body controller sends no actuator commands
SILENT_STATES = frozenset({S.COMM_DISABLED, S.IN_TEST_MODE})
_EXTRA_FAULTS = Fault.BODY_OVER_TEMPERATURE | Fault.BATTERY_PROTECTION
#: deliberate firmware bugs (``lowerbase emulate --robot legged --fault defect:NAME``): each
#: fails exactly its own checks of ``lowerbase conformance --robot legged`` (docs/conformance.md)
DEFECTS: dict[str, str] = {
    "no-velocity-timeout": "a stale BodyVelocityCommand stays in force (no command timeout)",
    "slow-status": "LocomotionStatus at twice its cycle time (40 ms)",
    "obey-outside-test-mode": "actuator commands from the upper side are obeyed and "
                              "answered in every state, not only IN_TEST_MODE",
    "no-exit-frames": "leaving motor mode sends no exit-motor-mode frames",
}


def _clamp(x: float, limit: float, low: float | None = None) -> float:
    return min(max(x, -limit if low is None else low), limit)


class LeggedLower:
    """The lower computer; ``send(bus, frame_id, data)`` puts a frame on leg bus ``bus``.

    ``bms``: a :class:`~lowerbase.bms.adapter.McuBmsAdapter` (None: no battery frames)."""

    def __init__(self, profile: LeggedProfile, clock: Clock, send: Send, *, bms: Any = None,
                 boot_counter: int = 1, codec: Codec | None = None,
                 defects: tuple[str, ...] = ()) -> None:
        self.profile, self.clock, self.send, self.bms = profile, clock, send, bms
        self.codec = codec or legged_codec()
        self.dt = DT
        self.body = profile.make_body()
        t = profile.thermal
        self.thermal = BodyThermal(t.body_thermal_mass, t.body_thermal_resistance, t.ambient_c)
        self.boot_counter = boot_counter
        self.boot_time = clock.now()
        self.stats: Counter[str] = Counter()
        self.tick = 0
        self.bms_snapshot: Any = None
        self._wire_state = self.body.state
        self._counters: dict[str, int] = {}
        self._bms_charge = self._bms_elapsed = 0.0
        self._bms_next_poll = self._bms_last_answer = self.boot_time
        self._was_fresh = False
        c = self.codec
        self._cmd = {mid: c.message(name) for mid, name in COMMAND_MESSAGES.items()}
        self._reply = c.message("MotorReply")
        self._request_id = c.message("LocomotionRequest").frame_id
        self._velocity_id = c.message("BodyVelocityCommand").frame_id
        self._periodic = [(m, round(m.cycle_time / DT)) for m in c
                          if m.is_periodic and "Body" in m.senders and m.cycle_time
                          and m.frame_id not in COMMAND_MESSAGES]
        self._values: dict[str, Callable[[], dict[str, float | int]]] = {
            "LocomotionStatus": self._status, "Heartbeat": self._heartbeat,
            "BaseVelocity": self._base_velocity, "BaseAngularVelocity": self._base_rate,
            "BasePosition": self._base_position, "BaseOrientation": self._orientation,
            "BodyTemperature": self._temperatures,
        }
        self.defects = frozenset(defects)
        unknown = self.defects - DEFECTS.keys()
        if unknown:
            raise ConfigError(f"unknown legged defect {sorted(unknown)[0]!r}; known: "
                              f"{', '.join(DEFECTS)}")
        if "no-velocity-timeout" in self.defects:  # defect hook (conformance)
            self.body.p = dataclasses.replace(self.body.p, command_timeout=math.inf)
        if "slow-status" in self.defects:  # defect hook (conformance)
            self._periodic = [(m, every * 2 if m.name == "LocomotionStatus" else every)
                              for m, every in self._periodic]

    # -- the upper side -----------------------------------------------------------------------

    def receive(self, bus: int, frame_id: int, data: bytes) -> None:
        """One frame from leg bus ``bus``; bad input is counted, never raised."""
        self.stats["rx_frames"] += 1
        if frame_id in COMMAND_MESSAGES:
            self._actuator_command(bus, frame_id, data)
            return
        if bus != BODY_BUS:
            self.stats["rx_wrong_bus"] += 1
            return
        if frame_id not in (self._request_id, self._velocity_id):
            self.stats["rx_ignored"] += 1
            return
        try:
            name, s = self.codec.decode(frame_id, data)
        except ProtocolError as exc:
            self.stats["rx_malformed"] += 1
            log.debug("dropped 0x%03X %s: %s", frame_id, data.hex(), exc)
            return
        if name == "LocomotionRequest":
            self.request(int(s["Request"]))
        else:
            self.body.velocity_command(float(s["Vx"]), float(s["Vy"]), float(s["YawRate"]))

    def request(self, target: int) -> RequestResult:
        """A LocomotionRequest: the body's state table, plus the lower computer's own faults
        (MOTOR_READY is refused while their cause lasts)."""
        body = self.body
        if target == S.MOTOR_READY and body.fault & _EXTRA_FAULTS and self._extra_cause():
            body.last_request, body.result = target, RequestResult.FAULTED
            return body.result
        return body.request(target)

    def _actuator_command(self, bus: int, frame_id: int, data: bytes) -> None:
        if self.body.state is not S.IN_TEST_MODE and \
                "obey-outside-test-mode" not in self.defects:  # defect hook (conformance)
            self.stats["rx_actuator_command_refused"] += 1
            return
        try:
            index = joint_index(bus, frame_id)
        except ValueError:
            self.stats["rx_wrong_bus"] += 1
            return
        a = self.body.actuators[index]
        special = parse_special(data)
        if special is not None:
            a.special(special)
        else:
            try:
                s = self._cmd[frame_id].decode(data)
            except ProtocolError:
                self.stats["rx_malformed"] += 1
                return
            a.set_command(float(s["Position"]), float(s["Velocity"]), float(s["Kp"]),
                          float(s["Kd"]), float(s["Torque"]))
            self.body.test_mode_commands += 1
        self._send_reply(bus, frame_id, a)

    # -- the control period -------------------------------------------------------------------

    def step(self) -> None:
        """One 1 ms period: models, actuator traffic, the body frames that are due."""
        body, dt = self.body, self.dt
        body.step(dt)
        losses = sum(copper_loss(a) for a in body.actuators)
        volts = self.bms_snapshot.voltage if self.bms_snapshot is not None else \
            self.profile.battery.nominal_voltage_v
        electronics = self.profile.battery.idle_current_a * volts
        self.thermal.step(dt, electronics + self.profile.thermal.motor_heat_fraction * losses)
        load = electrical_power(body.actuators, self.profile.power.drive_efficiency) / \
            max(volts, 1.0)
        self._update_bms(dt, load)
        self._check_faults()
        self._watchdog()
        self._actuator_traffic()
        for m, every in self._periodic:
            if self.tick % every == 0:
                self._send_periodic(m.name, m.frame_id)
        self.tick += 1

    def _watchdog(self) -> None:
        fresh = self.body.command_fresh
        if self._was_fresh and not fresh and self.body.state is S.IN_CONTROL:
            self.stats["velocity_command_timeouts"] += 1
        self._was_fresh = fresh

    def _actuator_traffic(self) -> None:
        state, before = self.body.state, self._wire_state
        self._wire_state = state
        special: Special | None = None
        if state is not before:
            if state is S.MOTOR_COMMUTATION:
                special = Special.ENTER_MOTOR_MODE
            elif state not in MOTOR_MODE_STATES and before in MOTOR_MODE_STATES and \
                    "no-exit-frames" not in self.defects:  # defect hook (conformance)
                special = Special.EXIT_MOTOR_MODE
        if special is None and state in SILENT_STATES:
            return
        for index in range(N_JOINTS):
            bus, mid = joint_address(index)
            a = self.body.actuators[index]
            if special is not None:
                data = special_frame(special)
            elif a.motor_mode:
                p, v, kp, kd, tau = a.command
                data = self._cmd[mid].encode({
                    "Position": _clamp(p, P_MAX), "Velocity": _clamp(v, V_MAX),
                    "Kp": _clamp(kp, KP_MAX, 0.0), "Kd": _clamp(kd, KD_MAX, 0.0),
                    "Torque": _clamp(tau, T_MAX[mid])})
            else:  # outside motor mode: zero gains (the firmware ignores it anyway)
                data = self._cmd[mid].encode({
                    "Position": _clamp(a.reported_position, P_MAX), "Velocity": 0.0,
                    "Kp": 0.0, "Kd": 0.0, "Torque": 0.0})
            self.send(bus, mid, data)
            self._send_reply(bus, mid, a)

    def _send_reply(self, bus: int, mid: int, a: Actuator) -> None:
        prefix = REPLY_PREFIX[mid]
        self.send(bus, REPLY_ID, self._reply.encode({
            "MotorId": mid, f"{prefix}Position": _clamp(a.reported_position, P_MAX),
            f"{prefix}Velocity": _clamp(a.velocity, V_MAX),
            f"{prefix}Torque": _clamp(a.torque, T_MAX[mid]),
            "Temperature": round(_clamp(a.temperature, 215.0, -40.0)), "Error": int(a.error)}))

    # -- faults and the battery ---------------------------------------------------------------

    def _extra_cause(self) -> bool:
        """Whether a body over-temperature or a battery protection is still present."""
        return self.thermal.temperature >= self.profile.thermal.body_clear_c or \
            self._battery_protection()

    def _battery_protection(self) -> bool:
        snap = self.bms_snapshot
        if snap is None:
            return False
        return not snap.switch_status & SwitchStatus.DISCHARGE or \
            snap.soc < self.profile.power.critical_battery_soc

    def _check_faults(self) -> None:
        if self.thermal.temperature >= self.profile.thermal.body_fault_c and \
                not self.body.fault & Fault.BODY_OVER_TEMPERATURE:
            self.body.external_fault(Fault.BODY_OVER_TEMPERATURE)
            log.warning("body over-temperature: %.1f degC", self.thermal.temperature)
        if self._battery_protection() and not self.body.fault & Fault.BATTERY_PROTECTION:
            self.body.external_fault(Fault.BATTERY_PROTECTION)
            log.warning("battery protection: the robot sits down")

    def _update_bms(self, dt: float, load_current: float) -> None:
        if self.bms is None:
            return
        self._bms_charge += load_current * dt
        self._bms_elapsed += dt
        if self._bms_elapsed >= BMS_STEP - 1e-9:
            self.bms.step(self._bms_elapsed, self._bms_charge / self._bms_elapsed)
            self._bms_charge = self._bms_elapsed = 0.0
        now = self.clock.now()
        if now < self._bms_next_poll:
            return
        self._bms_next_poll += BMS_POLL_PERIOD
        snapshot = self.bms.poll()
        if snapshot is not None:
            self.bms_snapshot = snapshot
            self._bms_last_answer = now

    # -- the body frames ----------------------------------------------------------------------

    def _send_periodic(self, name: str, frame_id: int) -> None:
        if name.startswith("Bms"):
            if self.bms is None or self.bms_snapshot is None or \
                    self.clock.now() - self._bms_last_answer > BMS_LINK_TIMEOUT:
                return
            values = dict(self.bms.frame(name, self.bms_snapshot))
        else:
            values = self._values[name]()
        counter = self._counters.get(name, 0)
        values["Counter"] = counter
        self._counters[name] = (counter + 1) % 16
        self.send(BODY_BUS, frame_id, self.codec.encode(name, values))

    def _status(self) -> dict[str, float | int]:
        b = self.body
        return {"State": int(b.state), "LastRequest": int(b.last_request),
                "RequestResult": int(b.result), "Fault": int(b.fault),
                "FaultJoint": int(b.fault_joint)}

    def _heartbeat(self) -> dict[str, float | int]:
        uptime = min(self.clock.now() - self.boot_time, 4294967.295)
        return {"Uptime": uptime, "BootCounter": self.boot_counter % 65536,
                "ProtocolVersion": PROTOCOL_VERSION,
                "Overruns": getattr(self.clock, "overruns", 0) % 16}

    def _base_velocity(self) -> dict[str, float | int]:
        b = self.body
        return {"Vx": _clamp(b.v[0], 32.767), "Vy": _clamp(b.v[1], 32.767),
                "Vz": _clamp(b.vz, 32.767)}

    def _base_rate(self) -> dict[str, float | int]:
        return {"Wx": 0.0, "Wy": 0.0, "Wz": _clamp(self.body.v[2], 32.767)}

    def _base_position(self) -> dict[str, float | int]:
        b = self.body
        return {"X": _clamp(b.x, 8388.607), "Y": _clamp(b.y, 8388.607),
                "Z": _clamp(b.height, 2.047)}

    def _orientation(self) -> dict[str, float | int]:
        x, y, z, w = self.body.quaternion()
        if w < 0:
            x, y, z, w = -x, -y, -z, -w
        return {"QX": x, "QY": y, "QZ": z, "QW": w}

    def _temperatures(self) -> dict[str, float | int]:
        temps = [a.temperature for a in self.body.actuators]
        hottest = max(range(N_JOINTS), key=temps.__getitem__)
        return {"Body": _clamp(self.thermal.temperature, 204.7),
                "ActuatorMax": _clamp(temps[hottest], 204.7), "HottestJoint": hottest}

    def shutdown(self) -> None:
        """Close the BMS (its link and any Modbus server)."""
        if self.bms is not None:
            self.bms.close()
