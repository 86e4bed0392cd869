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
   The actuators' 24 frames are encoded together, in compiled code (:func:`lowerbase.legged.
   kernels.traffic`); a ``send_batch(buses, frame_ids, payloads)`` given at construction gets
   them as arrays in one call (:class:`~lowerbase.simloop.legged.LeggedSimLoop`), else each
   goes to ``send`` in its order;
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

import numpy as np

from lowerbase.bms.status import SwitchStatus
from lowerbase.clock import Clock
from lowerbase.errors import ConfigError, EncodeError, ProtocolError
from lowerbase.legged import kernels
from lowerbase.legged.profile import LeggedProfile
from lowerbase.legged.thermal import BodyThermal
from lowerbase.protocol.codec import Codec
from lowerbase.protocol.legged import (
    BODY_BUS,
    COMMAND_MESSAGES,
    JOINT_NAMES,
    KD_MAX,
    KP_MAX,
    N_JOINTS,
    P_MAX,
    REPLY_ID,
    T_MAX,
    V_MAX,
    Fault,
    LocomotionState,
    RequestResult,
    Special,
    actuator_layouts,
    joint_address,
    joint_index,
    legged_codec,
    parse_special,
)

log = logging.getLogger(__name__)

S = LocomotionState
#: (bus, frame ID, payload) -> the wire
Send = Callable[[int, int, bytes], None]
#: (buses, frame IDs, payloads (n, 8) uint8) -> the wire, in row order; the arrays are reused
SendBatch = Callable[[np.ndarray, np.ndarray, np.ndarray], None]

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

    ``bms``: a :class:`~lowerbase.bms.adapter.McuBmsAdapter` (None: no battery frames);
    ``send_batch``: where the actuator traffic goes as one batch per period (None: to
    ``send``, frame by frame)."""

    def __init__(self, profile: LeggedProfile, clock: Clock, send: Send, *, bms: Any = None,
                 boot_counter: int = 1, codec: Codec | None = None,
                 defects: tuple[str, ...] = (), send_batch: SendBatch | None = None) -> None:
        self.profile, self.clock, self.send, self.bms = profile, clock, send, bms
        self.send_batch = send_batch
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
        self._protection_of: Any = None  # the snapshot _protection was made of
        self._protection = False
        self._wire_state = self.body.state
        self._counters: dict[str, int] = {}
        self._bms_charge = self._bms_elapsed = 0.0
        self._bms_next_poll = self._bms_last_answer = self.boot_time
        self._was_fresh = False
        c = self.codec
        self._cmd = {mid: c.message(name) for mid, name in COMMAND_MESSAGES.items()}
        self._request_id = c.message("LocomotionRequest").frame_id
        self._velocity_id = c.message("BodyVelocityCommand").frame_id
        self._traffic_tables()
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
        self._send_reply(bus, index)

    # -- the control period -------------------------------------------------------------------

    def step(self) -> None:
        """One 1 ms period: models, actuator traffic, the body frames that are due."""
        body, dt = self.body, self.dt
        body.step(dt)
        losses, electric = body.power.tolist()  # of the actuators' step just done
        volts = self.bms_snapshot.voltage if self.bms_snapshot is not None else \
            self.profile.battery.nominal_voltage_v
        electronics = self.profile.battery.idle_current_a * volts
        self.thermal.step(dt, electronics + self.profile.thermal.motor_heat_fraction * losses)
        load = max(electric, 0.0) / self.profile.power.drive_efficiency / max(volts, 1.0)
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
        out = self._encode_traffic(special)
        if self.send_batch is not None:
            self.send_batch(self._buses, self._ids, out)
            return
        data, send = out.tobytes(), self.send
        for k, (bus, frame_id) in enumerate(self._addresses):
            send(bus, frame_id, data[8 * k: 8 * k + 8])

    def _encode_traffic(self, special: Special | None) -> np.ndarray:
        """The period's 24 actuator frames (kernels.traffic), in a reused array."""
        bank, out, t = self.body.bank, self._frames, self._layouts
        bad = kernels.traffic(0 if special is None else int(special), bank.position,
                              bank.zero_offset, bank.velocity, bank.torque, bank.temperature,
                              bank.error, bank.motor_mode, bank.command, t.command_sig,
                              t.command_scale, t.reply_sig, t.reply_scale, self._limits,
                              t.big_endian, out)
        if bad >= 0:
            raise EncodeError(f"{JOINT_NAMES[bad // 2]}'s {('command', 'reply')[bad % 2]} "
                              f"does not encode: a value is not finite (its actuator's "
                              f"state is broken)")
        return out

    def _traffic_tables(self) -> None:
        """The actuator traffic's frames in kernels.traffic's order (per joint: its command,
        its reply) and the DBC layouts it encodes them by."""
        self._addresses = [a for i in range(N_JOINTS) for a in (
            joint_address(i), (joint_address(i)[0], REPLY_ID))]
        self._buses = np.array([b for b, _ in self._addresses], np.int64)
        self._ids = np.array([f for _, f in self._addresses], np.int64)
        self._frames = np.zeros((len(self._addresses), 8), np.uint8)
        self._reply_row, self._scratch = np.zeros(8, np.uint8), np.zeros(6)
        self._layouts = actuator_layouts(self.codec)
        self._limits = np.array([P_MAX, V_MAX, KP_MAX, KD_MAX,
                                 *(T_MAX[mid] for mid in sorted(COMMAND_MESSAGES))])
        self._encode_traffic(None)  # the kernel loaded now, not in the first period

    def _send_reply(self, bus: int, index: int) -> None:
        """Actuator ``index``'s answer to a command from the upper side (IN_TEST_MODE)."""
        b, row, t = self.body.bank, self._reply_row, self._layouts
        if not kernels.reply(index, b.position, b.zero_offset, b.velocity, b.torque,
                             b.temperature, b.error, t.reply_sig, t.reply_scale, self._limits,
                             t.big_endian, row, self._scratch):
            raise EncodeError(f"{JOINT_NAMES[index]}'s reply does not encode: a value is not "
                              f"finite (its actuator's state is broken)")
        self.send(bus, REPLY_ID, row.tobytes())

    # -- faults and the battery ---------------------------------------------------------------

    def _extra_cause(self) -> bool:
        """Whether a body over-temperature or a battery protection is still present."""
        return self.thermal.temperature >= self.profile.thermal.body_clear_c or \
            self._battery_protection()

    def _battery_protection(self) -> bool:
        snap = self.bms_snapshot
        if snap is None:
            return False
        if snap is not self._protection_of:  # a new snapshot (every BMS poll, 0.5 s)
            self._protection_of = snap
            self._protection = not snap.switch_status & SwitchStatus.DISCHARGE or \
                snap.soc < self.profile.power.critical_battery_soc
        return self._protection

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
