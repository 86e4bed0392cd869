"""The lean control period in compiled code: :class:`KernelLoop` drives
:func:`.lean_kernel.period` for :class:`~.fastloop.LeanLoop` (docs/emulator.md, "Where the time
goes").

One kernel call per period does the arithmetic; Python keeps what is rare or belongs to Python
objects: ``Mcu._target`` (smoother, watchdog), the IMU noise blocks, the BMS step and poll, the
odometer save, and the frames other than the hot ones. The state goes in and out as scalars
every period, so the Python objects (motors, encoders, ground truth, Mcu) are always current
for whoever reads or writes them between periods. The periodic frames' due times and the hot
frames' counters live in arrays while the kernel runs (``acquire``), and go back to the Mcu
before any Python path steps (``release``).

Slip events and random slip enter as data: ``SlipModel.event_fractions`` (the random draw,
the events in force) runs in Python before the call and its two fractions go into the
kernel's ``k`` (C_SLIP_L, C_SLIP_R; 0 without events), the kernel adds the acceleration slip.
So do active encoder, imu-freeze, overcurrent and stall faults: ``Mcu._fault_data``
(C_DROP_L, C_DROP_R, C_FROZEN, C_OVER_L, C_OVER_R, C_BLOCK_L, C_BLOCK_R: the encoders'
``dropout``, the IMU's ``frozen``, the drivers' injected over-current, which the kernel
latches before the motors step, the motors' ``blocked``). So do the other fault hooks
(``step(hooks=True)``, :meth:`KernelLoop.set_hooks`): the status bits the faults assert
(the button e-stop, which also latches ``Mcu.estop_command``; the bus error: C_FAULT_BITS),
the rolling counters' step (C_COUNT_STEP: 0 with the counter-stuck defect) and the
Heartbeat's cycle (``per``: twice with slow-heartbeat) go into the kernel; the BMS's
silence leaves the poll unanswered; the frames leave through ``Mcu._send_out`` (silence,
drop, corrupt, delay: drawn frame by frame in their order, as the Python period does) and
the delayed ones are released after the period's.
The BMS poll, every 100th period, is done before the kernel runs (``poll_ahead``: it reads
only the pack, which only the pack's step changes); in a period that also steps the pack
(every 20th, after the kernel) it is done after the step, and the status word is then made
again from its causes in Python (``LeanLoop._status``, LeanLoop's order). A period goes to
the Python LeanLoop instead (``step`` returns False, nothing changed) only when surroundings
are installed (the world's collision check, a Python callback, must see each move). The
signal layouts of the hot frames come from the codec (start bit, length, scale, offset,
signedness, raw range); a layout the kernel cannot encode (floats, Motorola order, integer
scaling) keeps the Python loop. Without numba, or when compilation fails, it is never used.
"""

from __future__ import annotations

import importlib
import logging
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from lowerbase.firmware_model import mcu_defs
from lowerbase.protocol.codec import MessageCodec

if TYPE_CHECKING:  # pragma: no cover
    from lowerbase.firmware_model.encoder import EncoderCounter
    from lowerbase.firmware_model.mcu_defs import McuParts, Send
    from lowerbase.firmware_model.motor import WheelMotor
    from lowerbase.firmware_model.profile import ChassisParams

log = logging.getLogger(__name__)

MAX_RUN = 60  #: periods per kernel call (at most 62: lean_batch keeps a bit per period in an int64)


class LeanParts(Protocol):
    """What the compiled loop uses of the Python lean loop (:class:`~.fastloop.LeanLoop`):
    the Mcu, its motors and encoders, the derived constants, the Python frame emitter."""

    mcu: McuParts
    ml: WheelMotor
    mr: WheelMotor
    el: EncoderCounter
    er: EncoderCounter
    ppr_l: float
    ppr_r: float
    bpp_l: float
    bpp_r: float
    imu_cycle: float
    stall_speed: float
    idle2: float

    def _derive(self, c: ChassisParams) -> None: ...
    def _status(self, now: float, hooks: bool = False) -> None: ...
    def _emit_due(self, now: float, hooks: bool = False) -> None: ...
    def send_rows(self, i: int, counters: dict[str, int], send: Send,
                  stuck: bool = False) -> int: ...

#: what the fault hooks give a kernel period (:meth:`KernelLoop.set_hooks`): the status bits
#: the faults assert, the rolling counters' step, the Heartbeat at twice its cycle
Hooks = tuple[int, int, bool]
NO_HOOKS: Hooks = (0, 1, False)


def hook_data(mcu: McuParts) -> Hooks:
    """What the fault hooks acting now give a period, compiled or in Python (LeanLoop's
    _status and _emit_due): the status bits of the button e-stop and of a bus fault, the
    rolling counters' step (0: counter-stuck), the Heartbeat at twice its cycle."""
    bits = mcu_defs.SB.ESTOP_BUTTON if mcu._active("estop") else 0
    if mcu._active("silence") or mcu._active("drop") or mcu._active("corrupt"):
        bits |= mcu_defs.SB.BUS_ERROR
    return (int(bits), 0 if mcu._active("defect", "counter-stuck") else 1,
            mcu._active("defect", "slow-heartbeat") is not None)

#: the hot frames: message, multiplexer value (None: plain), value slots after the Counter
HOT: dict[str, list[tuple[int | None, tuple[str, ...]]]] = {
    "WheelFeedback": [
        (0, ("Wheel", "LeftCount", "LeftVelocity", "LeftCurrent", "LeftDriverStatus")),
        (1, ("Wheel", "RightCount", "RightVelocity", "RightCurrent", "RightDriverStatus"))],
    "MotionState": [(None, ("Linear", "Angular"))],
    "ImuGyro": [(None, ("X", "Y", "Z"))],
    "ImuAccel": [(None, ("X", "Y", "Z"))],
}
_kernel: Any = None  # lean_kernel once it imported and compiled; False when it cannot


def kernel() -> tuple[Any, Any] | None:
    """The compiled kernel modules (lean_kernel, lean_batch), or None (numba missing or
    compilation failed)."""
    global _kernel
    if _kernel is None:
        try:
            lk = importlib.import_module("lowerbase.firmware_model.lean_kernel")
            lb = importlib.import_module("lowerbase.firmware_model.lean_batch")
            _warm_up(lk, lb)
            _kernel = lk, lb
        except Exception as exc:  # numba missing, or it cannot compile: the Python loop
            log.warning("the compiled control loop is not available (%s); using Python", exc)
            _kernel = False
    return _kernel or None


def tables(periodic: list[MessageCodec], lk: Any) -> tuple[np.ndarray, ...]:
    """(hot, frames, sig, scale) of :func:`.lean_kernel.emit` for the periodic messages, from
    their codecs; ValueError for a layout the kernel does not encode."""
    hot = np.zeros((len(periodic), 2), np.int64)
    frames: list[tuple[int, ...]] = []
    sig: list[tuple[int, ...]] = []
    scale: list[tuple[float, float]] = []
    bases = {"WheelFeedback": [lk.V_WF_L, lk.V_WF_R], "MotionState": [lk.V_MS],
             "ImuGyro": [lk.V_IG], "ImuAccel": [lk.V_IA]}
    for i, msg in enumerate(periodic):
        if msg.name not in HOT:
            continue
        if msg.big_endian or msg.length > 8 or not msg.has_counter:
            raise ValueError(f"{msg.name}: a layout the kernel does not encode")
        hot[i] = len(frames), len(HOT[msg.name])
        for (mux, names), base in zip(HOT[msg.name], bases[msg.name], strict=True):
            signals = msg.variants[mux] if mux is not None else msg.signals
            slots = ("Counter", *names)
            if {s.name for s in signals} != set(slots):
                raise ValueError(f"{msg.name}: signals {sorted(s.name for s in signals)}")
            frames.append((msg.frame_id, msg.length, len(sig), len(signals), base,
                           int(msg.name == "WheelFeedback")))
            for s in signals:
                if s.is_float or s.kind not in ("identity", "linear"):
                    raise ValueError(f"{msg.name}.{s.name}: a conversion the kernel lacks")
                sig.append((slots.index(s.name), s.start, s.length, int(s.kind == "linear"),
                            s.raw_min, s.raw_max))
                scale.append((s.scale, s.offset))
    return (hot, np.array(frames, np.int64).reshape(-1, 6), np.array(sig, np.int64).reshape(
        -1, 6), np.array(scale, np.float64).reshape(-1, 2))


def _warm_up(lk: Any, lb: Any) -> None:
    """Compile (or load from the cache) with the argument types of a real period."""
    k = np.ones(lk.C_SIZE + lk.R_SIZE)
    z, imu = np.zeros(12), np.zeros(12)
    due, per = np.zeros(2), np.ones(1)
    hot = np.zeros((1, 2), np.int64)
    counters, vals = np.zeros(1, np.int64), np.zeros(lk.V_SIZE)
    sig, scale = np.zeros((1, 6), np.int64), np.ones((1, 2))
    frames = np.zeros((1, 6), np.int64)
    out, ids, lens = np.zeros((8, 8), np.uint8), np.zeros(8, np.int64), np.zeros(8, np.int64)
    f, b, i = 0.0, False, 0
    lk.period(k, f, f, f, f, b, f, f, f, b, b, f, f, f, f, f, b, b, f, f, i, f, i, f,
              f, f, f, f, f, f, f, f, f, True, True, z, b, imu, i, True, f, f, f, i, i, i, i,
              b, b, f, b, True, due, per, hot, counters, vals, sig, scale, frames, out, ids,
              lens, i)
    lb.batch(k, np.zeros(lb.F_ODO_AT + 1), np.zeros(lb.J_FRESH + 1, np.int64), np.ones((1, 2)),
             np.zeros((1, 12)), imu, due, per, hot, counters, vals, sig, scale, frames, out,
             ids, lens, np.zeros(8, np.int64))


def _entry(fn: Any) -> Any:
    """The compiled entry point of a kernel compiled for one signature (``_warm_up``'s,
    which the KernelLoop's own arrays always match), skipping numba's type dispatch (about
    1 us of a call with 18 arrays); the dispatcher itself otherwise."""
    overloads = getattr(fn, "overloads", {})
    if len(overloads) != 1:
        return fn
    return getattr(next(iter(overloads.values())), "entry_point", fn)


class KernelLoop:
    """The compiled lean period of one Mcu (see the module docstring)."""

    def __init__(self, lean: LeanParts, lk: Any, lb: Any) -> None:
        self.lean, self.mcu, self.lk, self.m = lean, lean.mcu, lk, mcu_defs
        mcu = self.mcu
        self.hot, self.frames, self.sig, self.scale = tables(mcu._periodic, lk)
        n = len(mcu._periodic)
        self.hot_names = [(i, msg.name) for i, msg in enumerate(mcu._periodic)
                          if self.hot[i, 1]]
        self.due = np.zeros(n + 1)
        self.per = np.array([msg.cycle_time or 0.0 for msg in mcu._periodic])
        self.counters = np.zeros(n, np.int64)
        self.vals = np.zeros(lk.V_SIZE)
        self.imu = np.zeros(12)
        self.zero_row = np.zeros(12)
        self.lb = lb  # lean_batch: runs of periods (fastbatch.py drives them)
        self.batch = _entry(lb.batch)
        self.fs = np.zeros(lb.F_ODO_AT + MAX_RUN)  # the state of a run (lean_batch)
        self.js = np.zeros(lb.J_FRESH + MAX_RUN, np.int64)
        size = 5 * MAX_RUN + 2 * n + 8
        self.out, self.ids = np.zeros((size, 8), np.uint8), np.zeros(size, np.int64)
        self.lens, self.pidx = np.zeros(size, np.int64), np.zeros(size, np.int64)
        self.targets = np.zeros((MAX_RUN, 2))
        self.zero_rows = np.zeros((1, 12))
        self.k = np.zeros(lk.C_SIZE + lk.R_SIZE)
        self.k[lk.C_COUNT_STEP] = 1.0
        self.hooks = NO_HOOKS  #: the fault hooks' data in ``k`` and ``per`` (set_hooks)
        self.hb = [msg.name for msg in mcu._periodic].index("Heartbeat")
        self.owned = False
        self.slipping = False  #: slip fractions of events are in ``k`` (C_SLIP_L, C_SLIP_R)
        #: the Mcu._fault_data in ``k`` (C_DROP_L .. C_BLOCK_R)
        self._fault_data: mcu_defs.FaultData | None = None
        self._key: tuple[Any, ...] = ()

    # -- ownership of the due times, hot counters and IMU sample -----------------------------------

    def acquire(self) -> None:
        mcu = self.mcu
        self.due[:-1] = mcu._due
        self.due[-1] = mcu._next_any_due
        self._next = mcu._next_any_due
        for i, name in self.hot_names:
            self.counters[i] = mcu._counters[name]
        gyro, accel = mcu.imu_sample
        self.imu[6:] = (*gyro, *accel)
        self.lean.ml.blocked = self.lean.mr.blocked = False  # what _apply_faults does
        self.owned = True

    def release(self, hooks: bool = False) -> None:
        """Hand the due times and counters back to the Mcu (before any Python path steps);
        ``hooks``: a period with the fault hooks steps next (they may change the IMU's
        offsets and the wheels' flags)."""
        if hooks:
            self._key = ()
            self._fault_data = None
        if not self.owned:
            return
        mcu = self.mcu
        mcu._due = self.due[:-1].tolist()
        mcu._next_any_due = min(mcu._due)
        for i, name in self.hot_names:
            mcu._counters[name] = int(self.counters[i])
        self.owned = False

    def _constants(self) -> None:
        """The constants array for the current chassis, motor parameters and geometry."""
        mcu, lean, lk, m = self.mcu, self.lean, self.lk, self.m
        k, dt = self.k, mcu.dt
        for o, motor in ((0, lean.ml), (lk.M, lean.mr)):
            p, g = motor.params, motor.geometry
            if (p, g, dt) != motor._key:
                motor._constants(dt)
            k[o:o + lk.M] = (motor._limit, motor._alpha, p.time_constant, motor._ome_zero,
                             motor._ome_dt, motor._half_mass, motor._rolling, g.radius,
                             g.min_speed, p.viscous_friction, p.gear_efficiency, g.ratio,
                             p.torque_constant, p.idle_current, p.over_current_limit,
                             p.over_current_time, p.stall_speed, p.stall_time,
                             p.stall_current)
        c = mcu.chassis
        lean._derive(c)
        tg, sp, imu = mcu.truth.geometry, mcu.slip.params, mcu.imu
        ip = imu.params
        k[lk.C_DIST:lk.C_GF] = (
            c.wheel_distant, c.min_speed, c.wheel_perimeter, c.ratio_left, c.ratio_right,
            lean.bpp_l, lean.bpp_r, lean.ppr_l, lean.ppr_r,
            lean.stall_speed, sp.accel_slip_threshold, sp.accel_slip_fraction,
            tg.radius_left, tg.radius_right, tg.track, max(c.max_rpm, 1.0), lean.idle2,
            1.0 + ip.gyro_scale_error, 1.0 + ip.accel_scale_error, *imu._limits, ip.gravity,
            dt, 0.0, m.CARRIED, m.ENCODER_FAULT_TIME, m.IMU_FROZEN_SAMPLES,
            m.STANDBY_HINT_TIME, m.BMS_LINK_TIMEOUT)
        k[lk.C_GF:lk.C_SLIP_L] = (*imu.gyro_fault, *imu.accel_fault, *imu.gyro_turn_on,
                                *imu.accel_turn_on)
        rng = m._RANGES
        ranges = []
        for name, signals in (("WheelFeedback", ("LeftVelocity", "LeftCurrent")),
                              ("WheelFeedback", ("RightVelocity", "RightCurrent")),
                              ("MotionState", ("Linear", "Angular")),
                              ("ImuGyro", tuple("XYZ")), ("ImuAccel", tuple("XYZ"))):
            for s in signals:
                ranges += rng[name, s]
        k[lk.C_SIZE:] = ranges
        self._key = self._current_key()

    def set_fault_data(self, data: mcu_defs.FaultData) -> None:
        """The encoders' dropout, the IMU's freeze, the injected over-current and the wheels
        blocked (``Mcu._fault_data``) into the encoders, the IMU model, the motors and the
        kernel's data (C_DROP_L .. C_BLOCK_R; the kernel latches the over-current)."""
        lean = self.lean
        lean.el.dropout, lean.er.dropout, self.mcu.imu.frozen = data[:3]
        lean.ml.blocked, lean.mr.blocked = data[5:]
        self.k[self.lk.C_DROP_L:self.lk.C_BLOCK_R + 1] = data
        self._fault_data = data

    def set_hooks(self, hooks: Hooks) -> None:
        """The fault hooks' data (:data:`Hooks`, :func:`hook_data`) into ``k`` and ``per``."""
        bits, step, slow = hooks
        self.k[self.lk.C_FAULT_BITS] = bits
        self.k[self.lk.C_COUNT_STEP] = step
        cycle = self.mcu._periodic[self.hb].cycle_time or 0.0
        self.per[self.hb] = 2 * cycle if slow else cycle  # defect hook (conformance)
        self.hooks = hooks

    def no_slip(self) -> None:
        """No slip event in force: the kernel's event slip back to 0 (the runs' and any
        period's without events)."""
        self.k[self.lk.C_SLIP_L:self.lk.C_SLIP_R + 1] = 0.0
        self.slipping = False

    def _current_key(self) -> tuple[Any, ...]:
        lean, mcu = self.lean, self.mcu
        return (mcu.chassis, lean.ml.params, lean.ml.geometry, lean.mr.params, lean.mr.geometry,
                mcu.truth.geometry, mcu.slip.params)

    # -- one period ------------------------------------------------------------------------------

    def step(self, hooks: bool = False) -> bool:
        """One period in the kernel, ``hooks``: with the fault hooks acting (see the module
        docstring); False (nothing done) when it is the Python loop's."""
        mcu, m, lean = self.mcu, self.m, self.lean
        truth, slip, bms = mcu.truth, mcu.slip, mcu.bms
        now = mcu.clock.now()
        if truth.surroundings is not None:
            self.release(hooks)
            return False
        late_poll = (bms is not None and now >= mcu._bms_next_poll
                     and not self.poll_ahead(now, hooks and mcu._active("bms-silence")
                                             is not None))
        h = hook_data(mcu) if hooks else NO_HOOKS
        if h != self.hooks:
            self.set_hooks(h)
        if not self.owned:
            self.acquire()
        if self._key != self._current_key():
            self._constants()
        if slip.events or slip.params.slip_rate_per_km:  # the events' slip, as data
            self.k[self.lk.C_SLIP_L:self.lk.C_SLIP_R + 1] = slip.event_fractions(
                now - mcu.boot_time, truth.v * mcu.dt)
            self.slipping = True
        elif self.slipping:
            self.no_slip()
        if mcu._fault_data is not self._fault_data:  # encoder, imu-freeze, overcurrent, stall
            self.set_fault_data(mcu._fault_data)
        if mcu.state == m.RobotState.BOOT and now - mcu.boot_time >= m.BOOT_TIME:
            mcu.state = m.RobotState.STANDBY
        target_v, target_w, brake = mcu._target(now)
        imu = mcu.imu
        imu_due = now >= mcu._imu_due
        z = self.zero_row
        if imu_due and imu.params.noise:
            if not imu._left:
                imu._block(lean.imu_cycle if lean.imu_cycle > 0.0 else 1.0 / imu.params.rate_hz,
                           compiled=True)
            imu._left -= 1
            z = imu._arr[imu._left]
        ml, mr, el, er = lean.ml, lean.mr, lean.el, lean.er
        stuck = mcu._enc_stuck
        emit_now = now + 1e-9 >= self._next
        status_in, fault_in, state_in = mcu.status, mcu.motion_fault, mcu.state
        state, count = self.store_state(self.lk.period(
            self.k, now, mcu.boot_time, target_v, target_w, brake,
            ml.omega, ml.setpoint, ml.current, ml.over_current, ml.stalled, ml._over_time,
            ml._stall_time,
            mr.omega, mr.setpoint, mr.current, mr.over_current, mr.stalled, mr._over_time,
            mr._stall_time,
            el.total, el._frac, er.total, er._frac,
            truth.x, truth.y, truth.yaw, truth.v, truth.w, truth.distance,
            mcu.odometer, stuck["left"], stuck["right"],
            imu_due, imu.params.noise, z, mcu._imu_last is not None, self.imu, mcu._imu_same,
            bms is not None, mcu._bms_charge, mcu._bms_elapsed, mcu._bms_last_answer,
            mcu._bms_bits, mcu.status, mcu.motion_fault, int(mcu.state), mcu.estop_command,
            mcu._watchdog, mcu._standby_cmd_time,
            mcu._speed_limited and mcu._last_cmd is not None,
            emit_now, self.due, self.per, self.hot, self.counters, self.vals, self.sig,
            self.scale, self.frames, self.out, self.ids, self.lens, 0))
        ml._steady = mr._steady = None
        if bms is not None and mcu._bms_elapsed >= m.BMS_STEP - 1e-9:  # nothing above reads it
            bms.step(mcu._bms_elapsed, mcu._bms_charge / mcu._bms_elapsed)
            mcu._bms_charge = mcu._bms_elapsed = 0.0
        if late_poll:  # the poll after the pack's step, then the status word from its causes
            # again (the kernel's read the last poll's answer): LeanLoop's order, whose status
            # reads only what the kernel has stored by now; the hot frames read no status
            mcu._poll_bms(now, hooks and mcu._active("bms-silence") is not None)
            mcu.status, mcu.motion_fault, mcu.state = status_in, fault_in, state_in
            lean._status(now, hooks)
        else:
            if h[0] and mcu.status & m.SB.ESTOP_BUTTON:  # latched while pressed (_status)
                mcu.estop_command = True
            if state != mcu.state:
                mcu.state = m.RobotState(state)
        if imu_due:
            mcu._imu_due += lean.imu_cycle
            s = self.imu[6:].tolist()
            sample = ((s[0], s[1], s[2]), (s[3], s[4], s[5]))
            if imu.params.noise:
                zl = imu._arr[imu._left].tolist()
                gt, at, gb, ab = imu.gyro_turn_on, imu.accel_turn_on, imu.gyro_bias, imu.accel_bias
                gb[0], gb[1], gb[2] = gt[0] + zl[0], gt[1] + zl[1], gt[2] + zl[2]
                ab[0], ab[1], ab[2] = at[0] + zl[3], at[1] + zl[4], at[2] + zl[5]
            imu._last = mcu._imu_last = mcu.imu_sample = sample
        if mcu.odometer != mcu._saved_odometer and now - mcu._last_save >= m.ODOMETER_SAVE_PERIOD:
            mcu._save_state()
        if count:
            self._send(now, count, hooks)
        if mcu._delayed:
            mcu._release_delayed(now)
        return True

    def poll_ahead(self, now: float, silent: bool = False) -> bool:
        """The BMS poll of the period at ``now``, done before the kernel runs the period
        (LeanLoop polls after the period's current integration and pack step: the poll reads
        only the pack, which only the step changes); False, nothing done, when this period
        also steps the pack (the same float sum as the kernel's): the poll then comes after
        the period (``step``). ``silent``: the poll goes unanswered (the bms-silence fault)."""
        mcu, m = self.mcu, self.m
        bms = mcu.bms
        if bms is None or mcu._bms_elapsed + mcu.dt >= m.BMS_STEP - 1e-9:
            return False
        mcu._poll_bms(now, silent)
        return True

    def store_state(self, r: tuple[Any, ...]) -> tuple[Any, ...]:
        """Put the state a kernel call returned (``period``'s or ``batch``'s, the same leading
        33 scalars) back into the motors, encoders, ground truth and Mcu; returns the rest."""
        mcu, lean = self.mcu, self.lean
        ml, mr, el, er = lean.ml, lean.mr, lean.el, lean.er
        truth, stuck = mcu.truth, mcu._enc_stuck
        (ml.omega, ml.setpoint, ml.current, ml.over_current, ml.stalled, ml._over_time,
         ml._stall_time,
         mr.omega, mr.setpoint, mr.current, mr.over_current, mr.stalled, mr._over_time,
         mr._stall_time,
         el.total, el._frac, er.total, er._frac,
         truth.x, truth.y, truth.yaw, truth.v, truth.w, truth.accel_x, truth.distance,
         mcu.odometer, stuck["left"], stuck["right"], mcu._bms_charge, mcu._bms_elapsed,
         mcu._imu_same, mcu.status, mcu.motion_fault) = r[:33]
        return r[33:]

    def _send(self, now: float, count: int, hooks: bool = False) -> None:
        """The frames the kernel emitted (``count`` -1: the Python emitter's turn), through
        the fault hooks with ``hooks`` (``Mcu._send_out`` counts each frame then)."""
        if count < 0:  # a hot frame the codec refuses: the Python emitter raises as it did
            self.release()
            self.lean._emit_due(now, hooks)
            return
        self._next = float(self.due[-1])
        mcu = self.mcu
        sent = self.send_frames(self.out[:count].tobytes(), self.ids[:count].tolist(),
                                self.lens[:count].tolist(), 0, count,
                                mcu._send_out if hooks else mcu._send, self.hooks[1] == 0)
        if sent and not hooks:
            mcu.stats["tx_frames"] += sent

    def send_frames(self, data: bytes, ids: list[int], lens: list[int], start: int,
                    end: int, send: Send | None = None, stuck: bool = False) -> int:
        """Frames ``start`` .. ``end`` of an emission, in order, the non-hot ones built here
        (``data``: the payload slots, 8 bytes each; ``send``: the Mcu's unless given;
        ``stuck``: the counter-stuck defect); returns how many were built."""
        mcu = self.mcu
        send, counters = send or mcu._send, mcu._counters
        send_rows = self.lean.send_rows
        sent = 0
        for j in range(start, end):
            fid = ids[j]
            if fid >= 0:
                send(fid, data[8 * j:8 * j + lens[j]])
                sent += 1
            else:
                sent += send_rows(-1 - fid, counters, send, stuck)
        return sent
