"""The control period of :class:`~.mcu.Mcu`, once in Python: what ``Mcu.step`` runs.

A period runs in compiled code (fastkernel.py, lean_kernel.py) where numba is there and the
kernel takes it (not with surroundings installed: the world's collision check is a Python
callback), this Python loop being the reference it is tested against bit for bit; the faults
enter both as data. With ``hooks`` (a fault of faults.py acting other than those the
period always takes as data, or a delayed frame; ``Mcu.step``) the period also checks the
fault hooks: the faults' effects on the wheels, encoders and IMU (``Mcu._apply_faults``), the
button e-stop and bus-error bits, the BMS's silence, every frame out through
``Mcu._send_out`` (silence, drop, corrupt, delay), the conformance defects' counters and
Heartbeat cycle. tests/firmware_model/test_frame_trace.py pins the trace of a drive through
every fault kind (recorded with the emulator as it was before the speed work of issue 10),
compiled and in this Python period.

Constants of the hardware and of the believed chassis are derived once (again when
``Mcu.chassis`` is replaced); the 10 and 20 ms frames have builders of their own.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from lowerbase.clock import SimClock
from lowerbase.firmware_model import lean_bits as bits
from lowerbase.firmware_model import mcu_defs as m
from lowerbase.firmware_model.encoder import wrap_int32 as wrap
from lowerbase.firmware_model.fastkernel import NO_HOOKS, KernelLoop, hook_data, kernel

if TYPE_CHECKING:  # pragma: no cover
    from lowerbase.firmware_model.mcu_defs import McuParts, Send
    from lowerbase.firmware_model.profile import ChassisParams

Rows = list[dict[str, Any]]
log = logging.getLogger(__name__)
#: periodic messages whose values mostly repeat (16 LED submodules, the status word, the
#: system status between BMS polls): their payloads are kept by values (Counter included;
#: integers and the clipped voltage, so equal values encode to the same bytes)
MEMO = frozenset({"LedState", "StatusCode", "SystemStatus"})
MEMO_SIZE = 512  #: payloads kept per message before the memo starts again


class LeanLoop:
    """One Mcu's lean control period (built by ``Mcu.power_on``; see the module docstring)."""

    #: run the period in compiled code (fastkernel.py) when numba is there; False keeps this
    #: Python loop (the reference the kernel is tested against)
    compiled = True

    def __init__(self, mcu: McuParts) -> None:
        self.mcu = mcu
        self.m = m
        self.ml, self.mr = mcu._motors["left"], mcu._motors["right"]
        self.el, self.er = mcu._encoders["left"], mcu._encoders["right"]
        self.ppr_l = self.el.pulses_per_wheel_rad()  # hardware: fixed for the boot
        self.ppr_r = self.er.pulses_per_wheel_rad()
        self.imu_cycle = mcu._cycle("ImuGyro")
        self.stall_speed = mcu.profile.motor.stall_speed
        self.idle2 = mcu.profile.motor.idle_current * 2
        self._chassis: ChassisParams | None = None
        self.bpp_l = self.bpp_r = 0.0
        self.builders: list[Callable[[], Rows]] = [
            self._builder(msg.name) for msg in mcu._periodic]
        # the compiled encoder itself (what MessageCodec.encode calls when strict)
        self.tx = [(msg._encode, msg.name, msg.frame_id, msg.has_counter, msg.cycle_time or 0.0,
                    msg.name in m.SHARED_COUNTER) for msg in mcu._periodic]
        #: per periodic message whose values repeat (MEMO), its last payloads by values
        self.memo: list[dict[tuple[Any, ...], bytes] | None] = [
            {} if msg.name in MEMO else None for msg in mcu._periodic]
        self.kernel: KernelLoop | None = None
        # on a SimClock only: there the period's cost is the run's speed; in real time a period
        # costs 20 us of its 5 ms, and loading numba and the kernel (1-2 s) would delay the boot
        lk = kernel() if self.compiled and isinstance(mcu.clock, SimClock) else None
        if lk is not None:
            try:
                self.kernel = KernelLoop(self, *lk)
            except ValueError as exc:  # a frame layout the kernel does not encode
                log.warning("the compiled control loop is not used: %s", exc)

    def invalidate(self) -> None:
        """The IMU's offsets changed (a gyro bias step): the kernel derives its constants
        again before its next period."""
        if self.kernel is not None:
            self.kernel._key = ()

    def release(self) -> None:
        """Before a Python path steps: the compiled loop hands its state back to the Mcu."""
        if self.kernel is not None:
            self.kernel.release(hooks=True)

    # -- the believed chassis ------------------------------------------------------------------

    def _derive(self, c: ChassisParams) -> None:
        """Mcu._belief_per_pulse for both sides, for chassis ``c``."""
        self._chassis = c
        self.bpp_l = c.wheel_perimeter / (c.ratio_left * c.pulse_per_circle)
        self.bpp_r = c.wheel_perimeter / (c.ratio_right * c.pulse_per_circle)

    # -- one control period ----------------------------------------------------------------------

    def step(self, hooks: bool = False, kernel: bool = True) -> None:
        """One control period; ``hooks``: with the fault hooks (see the module docstring);
        ``kernel``: compiled if it may be (False: this Python period, the reference)."""
        if self.kernel is not None:
            if kernel and self.compiled and self.kernel.step(hooks):
                return
            self.kernel.release(hooks)
        mcu, m = self.mcu, self.m
        now = mcu.clock.now()
        dt = mcu.dt
        if mcu.state == m.RobotState.BOOT and now - mcu.boot_time >= m.BOOT_TIME:
            mcu.state = m.RobotState.STANDBY
        ml, mr, el, er = self.ml, self.mr, self.el, self.er
        if hooks:
            mcu._apply_faults()
        else:  # what Mcu._apply_faults does with only the faults of faults.DATA active
            el.dropout, er.dropout, mcu.imu.frozen, over_l, over_r, ml.blocked, mr.blocked = (
                mcu._fault_data)
            if over_l:  # the overcurrent fault
                ml.inject_over_current()
            if over_r:
                mr.inject_over_current()
        c = mcu.chassis
        if c is not self._chassis:
            self._derive(c)
        target_v, target_w, brake = mcu._target(now)
        # kinematics.wheel_speeds_from_twist and Mcu._wheel_target, inline
        half = 0.5 * target_w * c.wheel_distant
        v_l, v_r = target_v - half, target_v + half
        if abs(v_l) < c.min_speed:
            t_l = 0.0
        else:
            t_l = v_l * 2.0 * math.pi / c.wheel_perimeter * c.ratio_left / ml.geometry.ratio
        if abs(v_r) < c.min_speed:
            t_r = 0.0
        else:
            t_r = v_r * 2.0 * math.pi / c.wheel_perimeter * c.ratio_right / mr.geometry.ratio
        before_l, before_r = ml.omega, mr.omega
        truth = mcu.truth
        pressable = truth.surroundings is not None  # a refused move is redone pressed
        if pressable:
            saved_l, saved_r = ml.save(), mr.save()
        a_l = ml.step(t_l, dt, brake=brake)
        a_r = mr.step(t_r, dt, brake=brake)
        rim_accel = ((ml.omega - before_l) / dt * ml.geometry.radius,
                     (mr.omega - before_r) / dt * mr.geometry.radius)
        slip = mcu.slip.step(now - mcu.boot_time, truth.v * dt, rim_accel)
        truth.step(a_l / dt, a_r / dt, dt, slip, now + dt)
        held_l = held_r = False
        if pressable and truth.blocked:
            a_l = ml.press(saved_l, t_l, dt, brake=brake)
            a_r = mr.press(saved_r, t_r, dt, brake=brake)
            held_l, held_r = ml.held, mr.held
        moved_l = el.add(a_l)
        moved_r = er.add(a_r)
        ds = 0.0
        ds += 0.5 * moved_l * self.bpp_l
        ds += 0.5 * moved_r * self.bpp_r
        stuck = mcu._enc_stuck  # Mcu._check_encoder, both sides
        if abs(ml.setpoint) * ml.geometry.radius > self.stall_speed and moved_l == 0 \
                and not ml.blocked and not held_l:
            stuck["left"] += dt
        else:
            stuck["left"] = 0.0
        if abs(mr.setpoint) * mr.geometry.radius > self.stall_speed and moved_r == 0 \
                and not mr.blocked and not held_r:
            stuck["right"] += dt
        else:
            stuck["right"] = 0.0
        mcu.odometer += abs(ds)
        if now >= mcu._imu_due:
            mcu._sample_imu()
            mcu._imu_due += self.imu_cycle
        if mcu.bms is not None:
            self._bms(now, dt, c, hooks and mcu._active("bms-silence") is not None)
        self._status(now, hooks)
        if mcu.odometer != mcu._saved_odometer and now - mcu._last_save >= m.ODOMETER_SAVE_PERIOD:
            mcu._save_state()
        if now + 1e-9 >= mcu._next_any_due:
            self._emit_due(now, hooks)
        if mcu._delayed:
            mcu._release_delayed(now)

    def _bms(self, now: float, dt: float, c: ChassisParams, silent: bool = False) -> None:
        """The pack's charge and step, and its poll when due (none answered when ``silent``:
        the bms-silence fault), with Mcu.load_current inline. Stepping the pack in every
        period would cost more than the whole control loop: it integrates the charge over
        m.BMS_STEP exactly."""
        mcu, m = self.mcu, self.m
        total = self.idle2
        ml, mr = self.ml, self.mr
        top, two_pi = max(c.max_rpm, 1.0), 2.0 * math.pi  # WheelMotor.motor_rpm inline
        total += abs(ml.current) * (abs(ml.omega * ml.geometry.ratio * 60.0 / two_pi) / top)
        total += abs(mr.current) * (abs(mr.omega * mr.geometry.ratio * 60.0 / two_pi) / top)
        mcu._bms_charge += total * dt
        mcu._bms_elapsed += dt
        if mcu._bms_elapsed >= m.BMS_STEP - 1e-9:
            mcu.bms.step(mcu._bms_elapsed, mcu._bms_charge / mcu._bms_elapsed)
            mcu._bms_charge = mcu._bms_elapsed = 0.0
        if now >= mcu._bms_next_poll:
            mcu._poll_bms(now, silent)

    def _status(self, now: float, hooks: bool = False) -> None:
        """The status word from its causes (event-latched bits carried over) and the state it
        forces; with ``hooks``, the button e-stop and the bus faults too."""
        mcu, m = self.mcu, self.m
        s = mcu.status & m.CARRIED
        if hooks:  # the button e-stop, a bus fault
            s |= hook_data(mcu)[0]
        if mcu.estop_command:
            s |= bits.ESTOP_COMMAND
        if mcu._watchdog:
            s |= bits.WATCHDOG_STOP
        if now - mcu._standby_cmd_time < m.STANDBY_HINT_TIME:
            s |= bits.COMMAND_IN_STANDBY
        if mcu._speed_limited and mcu._last_cmd is not None:
            s |= bits.SPEED_LIMITED
        for motor, side, (over, stalled, fault, enc) in (
            (self.ml, "left", bits.SIDE_BITS[0]), (self.mr, "right", bits.SIDE_BITS[1])
        ):
            if motor.over_current:
                s |= over
            if motor.stalled:
                s |= stalled
            if motor.over_current or motor.stalled:
                s |= fault
                mcu.motion_fault |= fault
            if mcu._enc_stuck[side] >= m.ENCODER_FAULT_TIME:
                s |= enc
        s |= mcu.motion_fault
        if mcu._imu_same >= m.IMU_FROZEN_SAMPLES:
            s |= bits.IMU_FAULT
        if mcu.bms is not None:
            lost = now - mcu._bms_last_answer > m.BMS_LINK_TIMEOUT
            s |= (bits.BMS_LINK_LOST if lost else 0) | mcu._bms_bits
        # the button e-stop is latched only while pressed; releasing needs EStopRelease too
        if s & bits.ESTOP_BUTTON:
            mcu.estop_command = True
        mcu.status = s
        state = mcu.state
        rs = m.RobotState
        if state == rs.ACTIVE or state == rs.EMERGENCY_STOP or state == rs.FAULT:
            if s & bits.ESTOP_BITS:
                mcu.state = rs.EMERGENCY_STOP
            elif mcu.motion_fault or s & bits.BMS_PROTECTION:
                mcu.state = rs.FAULT
            elif state != rs.ACTIVE:
                mcu.state = rs.STANDBY

    # -- frames out ------------------------------------------------------------------------------

    def _emit_due(self, now: float, hooks: bool = False) -> None:
        """The periodic frames due now, in catalog order; a message late by more than its
        cycle skips the missed slots instead of bursting. Without ``hooks`` straight out with
        one stats update; with them through ``Mcu._send_out`` (which counts each frame) and
        the conformance defects slow-heartbeat and counter-stuck."""
        mcu = self.mcu
        due = mcu._due
        send_rows = self.send_rows
        counters = mcu._counters
        send = mcu._send_out if hooks else mcu._send
        _, step, slow = hook_data(mcu) if hooks else NO_HOOKS
        stuck = step == 0
        sent = 0
        edge = now + 1e-9
        for i, (_, name, _, _, period, _) in enumerate(self.tx):
            d = due[i]
            if edge < d:
                continue
            if slow and name == "Heartbeat":
                period *= 2  # defect hook (conformance)
            missed = max(0, math.floor((now - d) / period)) if period else 0
            due[i] = d + (missed + 1) * period
            sent += send_rows(i, counters, send, stuck)
        mcu._next_any_due = min(due)
        if sent and not hooks:
            mcu.stats["tx_frames"] += sent

    def send_rows(self, i: int, counters: dict[str, int], send: Send,
                  stuck: bool = False) -> int:
        """Build, count and send the rows of periodic message ``i`` (``self.tx[i]``): a shared
        rolling Counter for all rows, or one per row that lacks its own (``counters``,
        ``send``: the Mcu's; ``stuck``: the counters do not advance, the counter-stuck
        defect); returns how many frames were built (the Python emitter's and the kernel's
        non-hot frames both)."""
        encode, name, frame_id, has_counter, _, shared = self.tx[i]
        rows = self.builders[i]()
        step = 0 if stuck else 1
        if shared and rows and has_counter:
            counter = counters[name]
            counters[name] = (counter + step) & 0xF
            for values in rows:
                values["Counter"] = counter
        memo = self.memo[i]
        for values in rows:
            if has_counter and "Counter" not in values:
                values["Counter"] = counters[name]
                counters[name] = (counters[name] + step) & 0xF
            if memo is None:
                send(frame_id, encode(values))
                continue
            key = tuple(values.values())  # a builder always gives its keys in one order
            data = memo.get(key)
            if data is None:
                data = encode(values)
                if len(memo) >= MEMO_SIZE:
                    memo.clear()
                memo[key] = data
            send(frame_id, data)
        return len(rows)

    def _builder(self, name: str) -> Callable[[], Rows]:
        """The rows of periodic message ``name``: specialised for the 10 and 20 ms frames,
        Mcu._build for the others."""
        mcu, m = self.mcu, self.m
        rng = m._RANGES

        def clip(value: float, lo: float, hi: float) -> float:
            return lo if value < lo else hi if value > hi else value

        if name == "WheelFeedback":
            lv, hv = rng[name, "LeftVelocity"]
            lc, hc = rng[name, "LeftCurrent"]
            rlv, rhv = rng[name, "RightVelocity"]
            rlc, rhc = rng[name, "RightCurrent"]

            def wheel_feedback() -> Rows:
                ml, mr, el, er = self.ml, self.mr, self.el, self.er
                return [
                    {"LeftCount": wrap(el.total),
                     "LeftVelocity": clip(ml.omega * self.ppr_l * self.bpp_l, lv, hv),
                     "LeftCurrent": clip(ml.current, lc, hc), "Wheel": 0,
                     "LeftDriverStatus": ml.status_bits | el.status_bits},
                    {"RightCount": wrap(er.total),
                     "RightVelocity": clip(mr.omega * self.ppr_r * self.bpp_r, rlv, rhv),
                     "RightCurrent": clip(mr.current, rlc, rhc), "Wheel": 1,
                     "RightDriverStatus": mr.status_bits | er.status_bits}]
            return wheel_feedback
        if name == "MotionState":
            ll, hl = rng[name, "Linear"]
            la, ha = rng[name, "Angular"]

            def motion_state() -> Rows:
                v_l = self.ml.omega * self.ppr_l * self.bpp_l
                v_r = self.mr.omega * self.ppr_r * self.bpp_r
                v, w = 0.5 * (v_l + v_r), (v_r - v_l) / mcu.chassis.wheel_distant
                return [{"Linear": clip(v, ll, hl), "Angular": clip(w, la, ha)}]
            return motion_state
        if name in ("ImuGyro", "ImuAccel"):
            which = 0 if name == "ImuGyro" else 1
            (lx, hx), (ly, hy), (lz, hz) = (rng[name, axis] for axis in "XYZ")

            def imu() -> Rows:
                x, y, z = mcu.imu_sample[which]
                return [{"X": lx if x < lx else hx if x > hx else x,
                         "Y": ly if y < ly else hy if y > hy else y,
                         "Z": lz if z < lz else hz if z > hz else z}]
            return imu
        msg = mcu.codec.message(name)
        return lambda: mcu._build(msg)
