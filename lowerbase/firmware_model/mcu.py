"""The emulated lower computer: state machine, safety, frames in and out.

``Mcu`` is driven by whoever owns the clock: ``receive(frame_id, data)`` for every frame from
the upper computer and ``step()`` once per control period (``1 / rates.control_hz``). It sends
frames through the ``send(frame_id, data)`` callback at the catalog's cycle times. It never
reads the wall clock: on a ``SimClock`` an hour of driving takes seconds.

Safety as real firmware does it: standby after boot until ControlCommand EnableCanControl; a
command watchdog (commandTimeout) brakes to zero when MotionCommand stops arriving; e-stop
latches until EStopRelease (and then waits in standby to be enabled again); NaN, infinite and
out-of-range commands are rejected and flagged; FaultClear clears latched faults whose cause is
gone.
"""

from __future__ import annotations

import enum
import heapq
import logging
import math
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from lowerbase.clock import Clock
from lowerbase.errors import ConfigError, ProtocolError
from lowerbase.firmware_model import fastbatch, kinematics
from lowerbase.firmware_model.encoder import EncoderCounter
from lowerbase.firmware_model.fastloop import LeanLoop
from lowerbase.firmware_model.faults import Fault, parse_fault
from lowerbase.firmware_model.imu import ImuModel
from lowerbase.firmware_model.motor import WheelGeometry, WheelMotor
from lowerbase.firmware_model.parameters import SPECS, ParameterStore, Result, check
from lowerbase.firmware_model.profile import ChassisParams, Profile
from lowerbase.firmware_model.smoother import SmootherLimits, VelocitySmoother
from lowerbase.firmware_model.truth import GroundTruth, SlipModel, TrueGeometry
from lowerbase.protocol.codec import Codec, MessageCodec, default_codec
from lowerbase.protocol.status_codes import LATCHED as _LATCHED
from lowerbase.protocol.status_codes import STOPPING as _STOPPING
from lowerbase.protocol.status_codes import StatusBit

#: StatusBit as plain ints: IntFlag arithmetic costs microseconds per operation, and the
#: control loop does dozens per step
SB: Any = SimpleNamespace(**{str(b.name): int(b) for b in StatusBit})
LATCHED = int(_LATCHED)
STOPPING = int(_STOPPING)

ESTOP_BITS = SB.ESTOP_BUTTON | SB.ESTOP_COMMAND
#: latched bits set by an event (not recomputed each step); FaultClear clears them
CARRIED = (
    SB.COMMAND_REJECTED | SB.PARAMETER_ERROR | SB.PARAMETER_STORE_FAILED
)

log = logging.getLogger(__name__)

PROTOCOL_VERSION = 1
BOOT_TIME = 0.3  #: [s] from power-on to standby
BMS_POLL_PERIOD = 0.5  #: [s]
BMS_STEP = 0.1  #: [s] the pack model is stepped with the mean load over this period
BMS_LINK_TIMEOUT = 3.0  #: [s] without an answer -> BMS_LINK_LOST
ENCODER_FAULT_TIME = 0.2  #: [s] commanded motion without pulses -> encoder fault
IMU_FROZEN_SAMPLES = 20  #: identical consecutive samples -> IMU fault
STANDBY_HINT_TIME = 1.0  #: [s] COMMAND_IN_STANDBY stays set after the last such command
ODOMETER_SAVE_PERIOD = 1.0  #: [s] a changed odometer is persisted this often (a crash loses less)

#: messages sent as several frames per cycle that share the cycle's counter (the catalog says)
SHARED_COUNTER = frozenset({"WheelFeedback"})
LED_DEFAULT = {"Urgency": 0, "Abnormal": 0, "Normal": 0xA3, "Color": 0xFFFFFF}  # Idle, white
VALID_LED_NORMAL = frozenset(default_codec().message("LedCommand").signal("Normal").choices)


class RobotState(enum.IntEnum):
    BOOT = 0
    STANDBY = 1
    ACTIVE = 2
    EMERGENCY_STOP = 3
    FAULT = 4


class Command(enum.IntEnum):
    ENABLE_CAN_CONTROL = 1
    STANDBY = 2
    ESTOP_SET = 3
    ESTOP_RELEASE = 4
    FAULT_CLEAR = 5
    ODOMETER_RESET = 6
    REBOOT = 7


Send = Callable[[int, bytes], None]


class Mcu:
    """The chassis MCU. See the module docstring for the contract."""

    #: take the lean control loop (fastloop.py) whenever no fault is in play; False forces
    #: the general one (the tests compare the two)
    lean = True

    def __init__(
        self,
        profile: Profile,
        clock: Clock,
        send: Send,
        *,
        params_path: str | Path | None = None,
        bms: Any = None,
        faults: Iterable[Fault | str] = (),
        codec: Codec | None = None,
    ) -> None:
        self.profile = profile
        self.clock = clock
        self._send = send
        self.codec = codec or default_codec()
        self.store = ParameterStore(params_path)
        self.bms = bms  # lowerbase.bms device adapter: step(dt, load_current), poll(), frames
        self.dt = 1.0 / profile.rates.control_hz
        self.stats: Counter[str] = Counter()
        self.faults: list[Fault] = [f if isinstance(f, Fault) else parse_fault(f) for f in faults]
        self._rng = np.random.default_rng(profile.truth.seed + 1)
        self._periodic = [m for m in self.codec if m.is_periodic and "Lower" in m.senders]
        self._counters: dict[str, int] = {m.name: 0 for m in self.codec}
        self._delayed: list[tuple[float, int, int, bytes]] = []
        self._seq = 0
        self.boot_counter = 0
        self.odometer = 0.0
        self.truth = GroundTruth(TrueGeometry.from_profile(profile.chassis, profile.truth))
        self.slip = SlipModel(profile.truth)
        self.power_on()

    # -- boot --------------------------------------------------------------------------------

    def power_on(self) -> None:
        """Boot (also what Reboot does): load parameters, count the boot, start in BOOT."""
        old: LeanLoop | None = getattr(self, "_lean", None)
        if old is not None:
            old.release()  # the frame counters run on across a reboot
        params, state, problems = self.store.load()
        self.status = 0
        if problems:
            for p in problems:
                log.warning("%s", p)
            self.status |= SB.PARAMETER_ERROR
        try:
            self.chassis = ChassisParams.from_wire_dict(params, self.profile.chassis)
        except ConfigError as exc:
            log.warning("parameter file rejected (%s); profile defaults used", exc)
            self.chassis = self.profile.chassis
            self.status |= SB.PARAMETER_ERROR
        self.boot_counter = (int(state.get("boot_counter", self.boot_counter)) + 1) & 0xFFFF
        self.odometer = float(state.get("odometer", self.odometer))
        now = self.clock.now()
        self.boot_time = now
        self.state = RobotState.BOOT
        self.estop_command = False
        self.motion_fault = 0  # latched motor-fault bits
        self._last_cmd: tuple[float, float, int] | None = None
        self._last_cmd_time = -math.inf
        self._standby_cmd_time = -math.inf
        self._watchdog = False
        self._watchdog_ramp = False  # watchdog stop down the smoother's decel limits
        self._speed_limited = False
        #: the last command's limit_twist (linear, angular, chassis) -> result
        self._limited_key: tuple[float, float, ChassisParams] | None = None
        self._limited = kinematics.LimitedTwist(0.0, 0.0, clipped=False)
        # when each periodic message is due next, in catalog order (self._periodic)
        self._due = [now + (m.cycle_time or 0.0) for m in self._periodic]
        # like a CANopen boot-up message: the first frame after a boot is the Heartbeat with
        # the new BootCounter, so the upper side knows before any counter restarts at zero
        self._due[[m.name for m in self._periodic].index("Heartbeat")] = now
        self._next_any_due = min(self._due)
        # the hardware is the profile's (and never changes); the parameters are beliefs
        hw, true = self.profile.chassis, self.truth.geometry
        self._motors = {
            side: WheelMotor(self.profile.motor, WheelGeometry(
                true.radius_left if side == "left" else true.radius_right,
                hw.ratio_left if side == "left" else hw.ratio_right,
                0.0, self.chassis.max_rpm))  # the deadband is the firmware's (step)
            for side in ("left", "right")
        }
        self._encoders = {
            "left": EncoderCounter(hw.ratio_left, hw.pulse_per_circle),
            "right": EncoderCounter(hw.ratio_right, hw.pulse_per_circle),
        }
        self._enc_stuck = {"left": 0.0, "right": 0.0}
        self.smoother = VelocitySmoother(SmootherLimits.from_chassis(self.chassis))
        # a fresh turn-on bias and noise every boot, reproducible from the run seed
        self.imu = ImuModel(self.profile.imu,
                            np.random.default_rng([self.profile.imu.seed, self.boot_counter]))
        self._imu_last: tuple[Any, Any] | None = None
        self._imu_same = 0
        self._imu_due = now
        self.imu_sample = ((0.0, 0.0, 0.0), (0.0, 0.0, self.profile.imu.gravity))
        self.leds = {(strip, sub): dict(LED_DEFAULT) for strip in (0, 1) for sub in range(1, 9)}
        self._bms_last_answer = now
        self._bms_next_poll = now
        self._bms_bits = 0  # StatusCode bits of the last BMS reading
        self._bms_charge = 0.0  # [A*s] drawn since the pack was last stepped
        self._bms_elapsed = 0.0  # [s]
        self.bms_snapshot: Any = None
        self._imu_bias_applied = 0.0
        self._last_save = now
        self._save_state()
        self._lean = LeanLoop(self)
        log.info("boot #%d", self.boot_counter)

    def _save_state(self) -> None:
        try:
            self.store.save(self.chassis.as_wire_dict(), {
                "boot_counter": self.boot_counter, "odometer": round(self.odometer, 6)})
        except OSError as exc:
            log.error("cannot write the parameter file: %s", exc)
            self.status |= SB.PARAMETER_STORE_FAILED
            return
        self._last_save = self.clock.now()
        self._saved_odometer = self.odometer

    def shutdown(self) -> None:
        """Persist the odometer and boot counter (a clean power-off)."""
        self._save_state()

    # -- faults ------------------------------------------------------------------------------

    def inject(self, fault: Fault | str) -> Fault:
        """Start a fault now (relative times are counted from boot)."""
        f = fault if isinstance(fault, Fault) else parse_fault(fault)
        if f.start == 0.0:
            f = replace(f, start=self.clock.now() - self.boot_time)
        self.faults.append(f)
        return f

    def clear_fault(self, kind: str | None = None) -> None:
        """End injected faults of ``kind`` (all with None)."""
        self.faults = [f for f in self.faults if kind is not None and f.kind != kind]

    def _active(self, kind: str, arg: str | None = None) -> Fault | None:
        if not self.faults:
            return None
        t = self.clock.now() - self.boot_time
        for f in self.faults:
            if f.kind == kind and (arg is None or f.arg == arg) and f.active(t):
                return f
        return None

    # -- receiving ---------------------------------------------------------------------------

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

    def _wheel_target(self, side: str, rim: float) -> float:
        """What the firmware makes the real wheel do [rad/s] for a commanded rim speed [m/s]:
        the motor speed its beliefs give (rim / believed radius x believed ratio; the minSpeed
        deadband), turned by the REAL gearbox."""
        c = self.chassis
        if abs(rim) < c.min_speed:
            return 0.0
        ratio = c.ratio_left if side == "left" else c.ratio_right
        motor_rad_s = kinematics.rim_speed_to_wheel_rad_s(rim, c.wheel_perimeter) * ratio
        return motor_rad_s / self._motors[side].geometry.ratio

    def _belief_per_pulse(self, side: str) -> float:
        """Rim distance [m] the firmware counts per encoder pulse (its parameters)."""
        c = self.chassis
        ratio = c.ratio_left if side == "left" else c.ratio_right
        return c.wheel_perimeter / (ratio * c.pulse_per_circle)

    def wheel_velocity(self, side: str) -> float:
        """The reported rim speed [m/s] (WheelFeedback.Left/RightVelocity): the real motor speed as
        the encoder measures it, converted with the believed pulsePerCircle, ratio and perimeter."""
        motor, enc = self._motors[side], self._encoders[side]
        pulses_per_s = motor.omega * enc.pulses_per_wheel_rad()
        return pulses_per_s * self._belief_per_pulse(side)

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

    # -- the control loop --------------------------------------------------------------------

    def step(self) -> None:
        """One control period: safety, motion, sensors, BMS, then the frames that are due."""
        if self.lean and not (self.faults or self._delayed or self._imu_bias_applied
                              or self.imu.frozen):
            self._lean.step()  # the same, bit for bit, without the fault hooks (fastloop.py)
            return
        self._lean.release()  # the compiled lean loop's due times and counters, back here
        now = self.clock.now()
        dt = self.dt
        if self.state == RobotState.BOOT and now - self.boot_time >= BOOT_TIME:
            self.state = RobotState.STANDBY
        self._apply_faults()
        target_v, target_w, brake = self._target(now)
        c = self.chassis
        v_l, v_r = kinematics.wheel_speeds_from_twist(target_v, target_w, c.wheel_distant)
        targets = {"left": self._wheel_target("left", v_l),
                   "right": self._wheel_target("right", v_r)}
        angles, accel = {}, {}
        for side, motor in self._motors.items():
            before = motor.omega
            angles[side] = motor.step(targets[side], dt, brake=brake)
            accel[side] = (motor.omega - before) / dt * motor.geometry.radius  # real rim
        rim_accel = (accel["left"], accel["right"])
        slip = self.slip.step(now - self.boot_time, self.truth.v * dt, rim_accel)
        self.truth.step(angles["left"] / dt, angles["right"] / dt, dt, slip, now + dt)
        ds = 0.0
        for side, enc in self._encoders.items():
            before = enc.total
            enc.add(angles[side])
            moved = enc.total - before
            ds += 0.5 * moved * self._belief_per_pulse(side)
            self._check_encoder(side, moved, dt)
        self.odometer += abs(ds)
        if now >= self._imu_due:
            self._sample_imu()
            self._imu_due += self._cycle("ImuGyro")
        self._update_bms(now, dt)
        self._update_status(now)
        if self.odometer != self._saved_odometer and now - self._last_save >= ODOMETER_SAVE_PERIOD:
            self._save_state()
        self._emit_due(now)
        self._release_delayed(now)

    def advance(self, periods: int) -> None:
        """``periods`` control periods on a SimClock, each followed by ``clock.advance(dt)``:
        what a loop of ``step()`` and ``clock.advance(dt)`` does, frame for frame, with runs of
        lean periods in one compiled call (fastbatch.py; the send callback must then not read
        this Mcu or its truth: a run's state comes back once, its frames after it)."""
        clock = self.clock
        while periods > 0:
            kernel = self._lean.kernel
            done = 0
            if (kernel is not None and self.lean and self._lean.compiled
                    and not (self.faults or self._delayed or self._imu_bias_applied
                             or self.imu.frozen)):
                done = fastbatch.run(kernel, periods)
            if not done:
                self.step()
                clock.advance(self.dt)  # type: ignore[attr-defined]  # a SimClock
                done = 1
            periods -= done

    def _target(self, now: float) -> tuple[float, float, bool]:
        """Twist to drive (after limits and smoothing) and whether to brake."""
        stop = bool(self.status & STOPPING) or self.estop_command or self.motion_fault
        if self.state != RobotState.ACTIVE or stop:
            self.smoother.reset(*self._measured_twist())
            self._watchdog = self._watchdog_ramp = False
            return 0.0, 0.0, True
        timed_out = now - self._last_cmd_time > self.chassis.command_timeout
        if timed_out and self._active("defect", "no-watchdog"):  # defect hook (conformance)
            timed_out = False
        if self._last_cmd is None or timed_out:
            moving = any(abs(m.omega) > 1e-9 for m in self._motors.values())
            # braking because commands stopped while the robot moved or was told to move; a
            # robot at rest after a zero command that simply hears nothing more is not stopped
            # by the watchdog
            asked = self._last_cmd is not None and (self._last_cmd[0] or self._last_cmd[1])
            self._watchdog = self._watchdog or moving or bool(asked)
            if self._last_cmd is not None:  # the deadline has just passed
                self._watchdog_ramp = self._last_cmd[2] == 1
            self._last_cmd = None
            if self._watchdog_ramp and (self.smoother.v or self.smoother.w):
                # after Smoothed commands: slow down at linear/angularDecelLimit, as ROS
                # diff_drive_controller's limiter does on a command timeout (a load on the
                # robot stays put), then brake; Raw commands brake at the motor's limit
                v, w = self.smoother.step(0.0, 0.0, self.dt)
                return v, w, False
            self._watchdog_ramp = False
            self.smoother.reset(*self._measured_twist())
            return 0.0, 0.0, True
        self._watchdog = self._watchdog_ramp = False
        v, w, mode = self._last_cmd
        if mode == 1:
            v, w = self.smoother.step(v, w, self.dt)
        else:
            self.smoother.reset(v, w)
        return v, w, False

    def _measured_twist(self) -> tuple[float, float]:
        return kinematics.twist_from_wheel_speeds(
            self.wheel_velocity("left"), self.wheel_velocity("right"), self.chassis.wheel_distant)

    def _apply_faults(self) -> None:
        if not self.faults and not self._imu_bias_applied and not self.imu.frozen:
            for side in ("left", "right"):
                self._motors[side].blocked = False
                self._encoders[side].dropout = False
            return
        for side in ("left", "right"):
            self._motors[side].blocked = self._active("stall", side) is not None
            if self._active("overcurrent", side):
                self._motors[side].inject_over_current()
            self._encoders[side].dropout = self._active("encoder", side) is not None
        self.imu.freeze(self._active("imu-freeze") is not None)
        bias = self._active("imu-bias")
        want = bias.value if bias else 0.0
        if want != self._imu_bias_applied:
            self.imu.bias_step(gyro=(0.0, 0.0, want - self._imu_bias_applied))
            self._imu_bias_applied = want

    def _check_encoder(self, side: str, moved: int, dt: float) -> None:
        motor = self._motors[side]
        commanded = abs(motor.setpoint) * motor.geometry.radius > self.profile.motor.stall_speed
        if commanded and moved == 0 and not motor.blocked:
            self._enc_stuck[side] += dt
        else:
            self._enc_stuck[side] = 0.0

    def _sample_imu(self) -> None:
        gyro, accel = self.imu.sample(self.truth.body_omega, self.truth.body_accel,
                                      self._cycle("ImuGyro"))
        sample = (gyro, accel)
        if self._imu_last is not None and sample == self._imu_last:
            self._imu_same += 1
        else:
            self._imu_same = 0
        self._imu_last = sample
        self.imu_sample = sample

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

    # -- sending -----------------------------------------------------------------------------

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
                     "BootCounter": self.boot_counter, "ProtocolVersion": PROTOCOL_VERSION}]
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

    # -- views for tests and benches (never on the bus) ----------------------------------------

    def encoder_counts(self) -> tuple[int, int]:
        return self._encoders["left"].count, self._encoders["right"].count

    @property
    def motors(self) -> dict[str, WheelMotor]:
        return self._motors


_RANGES: dict[tuple[str, str], tuple[float, float]] = {
    (m.name, s.name): (
        s.minimum if s.minimum is not None else -math.inf,
        s.maximum if s.maximum is not None else math.inf,
    )
    for m in default_codec() for s in m.signals
}


def _clip(value: float, msg: MessageCodec, signal: str) -> float:
    """Saturate a measurement at its signal's range, as a sensor register does."""
    lo, hi = _RANGES[msg.name, signal]
    return lo if value < lo else hi if value > hi else value
