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

import logging
import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from lowerbase.clock import Clock
from lowerbase.errors import ConfigError
from lowerbase.firmware_model import fastbatch, kinematics
from lowerbase.firmware_model.encoder import EncoderCounter
from lowerbase.firmware_model.fastkernel import MAX_RUN, KernelLoop
from lowerbase.firmware_model.fastloop import LeanLoop
from lowerbase.firmware_model.faults import (
    LEAN,
    Fault,
    any_active,
    parse_fault,
    quiet_periods,
)
from lowerbase.firmware_model.imu import ImuModel
from lowerbase.firmware_model.mcu_commands import McuCommands
from lowerbase.firmware_model.mcu_defs import (  # re-exported: the names import from here
    _RANGES,
    BMS_LINK_TIMEOUT,
    BMS_POLL_PERIOD,
    BMS_STEP,
    BOOT_TIME,
    CARRIED,
    ENCODER_FAULT_TIME,
    ESTOP_BITS,
    IMU_FROZEN_SAMPLES,
    LATCHED,
    LED_DEFAULT,
    NO_FAULT_DATA,
    ODOMETER_SAVE_PERIOD,
    PROTOCOL_VERSION,
    SB,
    SHARED_COUNTER,
    STANDBY_HINT_TIME,
    STOPPING,
    VALID_LED_NORMAL,
    Command,
    RobotState,
    Send,
    _clip,
)
from lowerbase.firmware_model.mcu_frames import McuFrames
from lowerbase.firmware_model.motor import WheelGeometry, WheelMotor
from lowerbase.firmware_model.parameters import ParameterStore
from lowerbase.firmware_model.profile import ChassisParams, Profile
from lowerbase.firmware_model.smoother import SmootherLimits, VelocitySmoother
from lowerbase.firmware_model.truth import GroundTruth, SlipModel, TrueGeometry
from lowerbase.protocol.codec import Codec, default_codec

__all__ = [
    "BMS_LINK_TIMEOUT",
    "BMS_POLL_PERIOD",
    "BMS_STEP",
    "BOOT_TIME",
    "CARRIED",
    "ENCODER_FAULT_TIME",
    "ESTOP_BITS",
    "IMU_FROZEN_SAMPLES",
    "LATCHED",
    "LED_DEFAULT",
    "ODOMETER_SAVE_PERIOD",
    "PROTOCOL_VERSION",
    "SB",
    "SHARED_COUNTER",
    "STANDBY_HINT_TIME",
    "STOPPING",
    "VALID_LED_NORMAL",
    "_RANGES",
    "Command",
    "Mcu",
    "RobotState",
    "Send",
    "_clip",
]

log = logging.getLogger(__name__)


class Mcu(McuCommands, McuFrames):
    """The chassis MCU. See the module docstring for the contract."""

    #: compiled periods where they may be, the fault hooks checked only where a fault acts
    #: (fastloop.py); False: the Python period with every hook checked in every period (the
    #: reference the tests compare with)
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
        #: the last MotionCommand accepted through advance(incoming=...) (fastbatch._remember)
        self._repeat_of: tuple[Any, ...] | None = None
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
        #: the encoders' dropout (left, right), the IMU frozen, the drivers' injected
        #: over-current (left, right), the wheels blocked (left, right), for the lean periods
        self._fault_data = NO_FAULT_DATA
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

    def _apply_bias(self) -> None:
        """Add the imu-bias fault's gyro bias step, or take it back, when it changes (the IMU
        model carries it in between; the compiled period reads it from its constants)."""
        bias = self._active("imu-bias")
        want = bias.value if bias else 0.0
        if want != self._imu_bias_applied:
            self.imu.bias_step(gyro=(0.0, 0.0, want - self._imu_bias_applied))
            self._imu_bias_applied = want
            self._lean.invalidate()

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

    # -- the control loop --------------------------------------------------------------------

    def step(self) -> None:
        """One control period: safety, motion, sensors, BMS, then the frames that are due
        (fastloop.py: compiled where it may be, faults entering as data; the fault hooks
        checked only while a fault acts that the period does not always take as data, or a
        frame is delayed)."""
        if not self.lean:  # the reference: every hook checked, in Python, in every period
            self._lean.step(True, kernel=False)
            return
        hooks = bool(self._delayed)
        if self.faults or self._imu_bias_applied:
            self._apply_bias()
            hooks = hooks or any_active(self.faults, self.clock.now() - self.boot_time, LEAN)
            # encoder, imu-freeze, overcurrent, stall: data for every period
            self._fault_data = (self._active("encoder", "left") is not None,
                                self._active("encoder", "right") is not None,
                                self._active("imu-freeze") is not None,
                                self._active("overcurrent", "left") is not None,
                                self._active("overcurrent", "right") is not None,
                                self._active("stall", "left") is not None,
                                self._active("stall", "right") is not None)
        elif self._fault_data is not NO_FAULT_DATA:
            self._fault_data = NO_FAULT_DATA
        self._lean.step(hooks)

    def advance(self, periods: int, incoming: fastbatch.Incoming = ()) -> None:
        """``periods`` control periods on a SimClock, each followed by ``clock.advance(dt)``:
        what a loop of ``step()`` and ``clock.advance(dt)`` does, frame for frame, with runs of
        lean periods in one compiled call (fastbatch.py; the send callback must then not read
        this Mcu or its truth: a run's state comes back once, its frames after it).
        ``incoming``: frames from the upper side, ``(k, frame_id, data)`` received just before
        period k (in period order): a run then spans repeated MotionCommands
        (:func:`.fastbatch.advance`)."""
        if incoming:
            fastbatch.advance(self, periods, incoming, self._kernel_for_run)
            return
        clock = self.clock
        while periods > 0:
            runs = self._kernel_for_run()
            done = 0
            if runs is not None:
                done = fastbatch.run(runs[0], min(periods, runs[1]))
            if not done:
                self.step()
                clock.advance(self.dt)  # type: ignore[attr-defined]  # a SimClock
                done = 1
            periods -= done

    def _kernel_for_run(self) -> tuple[KernelLoop, int] | None:
        """The compiled loop and how many periods a run may take from now (none with a fault
        active), or None when no run may be taken now."""
        kernel = self._lean.kernel
        if (kernel is None or not self.lean or not self._lean.compiled or self._delayed
                or self._imu_bias_applied or self.imu.frozen):
            return None
        most = MAX_RUN if not self.faults else quiet_periods(
            self.faults, self.clock.now() - self.boot_time, self.dt, MAX_RUN)
        return (kernel, most) if most else None

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

    def load_current(self) -> float:
        """Battery current drawn by the motor drivers [A] (positive = discharge). The
        electronics (computers, sensors, LEDs) are the battery's ``idle_current_a``, counted
        by the pack model once (fastloop.LeanLoop._bms has this inline)."""
        total = self.profile.motor.idle_current * 2
        for motor in self._motors.values():
            # electrical power ~ torque current x motor speed share, at the pack voltage
            rpm_share = abs(motor.motor_rpm) / max(self.chassis.max_rpm, 1.0)
            total += abs(motor.current) * rpm_share
        return total

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
        self._apply_bias()

    def _poll_bms(self, now: float, silent: bool = False) -> None:
        """The BMS poll due at ``now``; unanswered when ``silent`` (the bms-silence fault)."""
        self._bms_next_poll += BMS_POLL_PERIOD
        snapshot = None if silent else self.bms.poll()
        if snapshot is not None:
            self.bms_snapshot = snapshot
            self._bms_bits = int(self.bms.status_bits(snapshot))
            self._bms_last_answer = now

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

    # -- views for tests and benches (never on the bus) ----------------------------------------

    def encoder_counts(self) -> tuple[int, int]:
        return self._encoders["left"].count, self._encoders["right"].count

    @property
    def motors(self) -> dict[str, WheelMotor]:
        return self._motors


