"""``Mcu.advance`` through the compiled loop: a run of lean periods in one kernel call
(:func:`.lean_batch.batch`), then their frames sent period by period, each at its time.

A run is taken while the robot drives on a command (ACTIVE, nothing stopping it, a command in
force): ``Mcu._target`` is then a function of the command and the smoother alone, computed here
for every period of the run (the smoother wound back if the run stops early). The state
comes back once per run, so during a run the send callback must not read the Mcu or its ground
truth (SimRig and the fleet's buses do not; the frames themselves are exact).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, cast

from lowerbase.clock import SimClock
from lowerbase.firmware_model.fastkernel import MAX_RUN, NO_HOOKS

if TYPE_CHECKING:  # pragma: no cover
    from lowerbase.firmware_model.fastkernel import KernelLoop
    from lowerbase.firmware_model.mcu_defs import McuParts

__all__ = ["MAX_RUN", "Incoming", "advance", "run"]


def run(kl: KernelLoop, n: int, fresh: Sequence[int] = ()) -> int:
    """Up to ``n`` periods (each followed by ``clock.advance(dt)``); returns how many were
    done, 0 when the next one is not for a run (the caller steps it). ``fresh``: the periods
    (from 0, ascending) before which the last MotionCommand arrives again (``Mcu.advance``
    checked that it is the same command: only its watchdog time changes)."""
    mcu, m, lean, lb = kl.mcu, kl.m, kl.lean, kl.lb
    truth, slip, bms = mcu.truth, mcu.slip, mcu.bms
    cmd = mcu._last_cmd
    if (cmd is None or mcu.state != m.RobotState.ACTIVE or mcu.status & m.STOPPING
            or mcu.estop_command or mcu.motion_fault or truth.surroundings is not None
            or slip.events or slip.params.slip_rate_per_km):
        return 0
    now = mcu.clock.now()
    imu = mcu.imu
    noise = imu.params.noise
    if noise and not imu._left:  # the next sample's noise block, drawn now: the same numbers,
        # as only the IMU draws from its generator (a boot makes a new one)
        imu._block(lean.imu_cycle if lean.imu_cycle > 0.0 else 1.0 / imu.params.rate_hz,
                   compiled=True)
    if bms is not None and now >= mcu._bms_next_poll and not kl.poll_ahead(now):
        return 0
    if not kl.owned:
        kl.acquire()
    if kl._key != kl._current_key():
        kl._constants()
    if kl.slipping:
        kl.no_slip()
    if kl._fault_data is not m.NO_FAULT_DATA:  # no fault is active in a run (_kernel_for_run)
        mcu._fault_data = m.NO_FAULT_DATA
        kl.set_fault_data(m.NO_FAULT_DATA)
    if kl.hooks != NO_HOOKS:  # nor a fault hook
        kl.set_hooks(NO_HOOKS)
    n = min(n, MAX_RUN)
    v, w, mode = cmd
    targets = kl.targets
    smoother = mcu.smoother
    dt = mcu.dt
    wound: list[tuple[float, float]] = []
    start = smoother.v, smoother.w
    if mode == 1:
        for j in range(n):
            targets[j] = smoother.step(v, w, dt)
            wound.append((smoother.v, smoother.w))
    ml, mr, el, er = lean.ml, lean.mr, lean.el, lean.er
    stuck = mcu._enc_stuck
    imu_due0 = mcu._imu_due
    fs, js = kl.fs, kl.js
    status_in, state_in = mcu.status, mcu.state  # motion_fault is 0 here
    fs[:lb.F_IN] = (
        ml.omega, ml.setpoint, ml.current, ml._over_time, ml._stall_time,
        mr.omega, mr.setpoint, mr.current, mr._over_time, mr._stall_time,
        el._frac, er._frac, truth.x, truth.y, truth.yaw, truth.v, truth.w, truth.accel_x,
        truth.distance, mcu.odometer, stuck["left"], stuck["right"], mcu._bms_charge,
        mcu._bms_elapsed, imu_due0, now, mcu.boot_time, v, w, lean.imu_cycle,
        mcu._bms_last_answer, mcu._bms_next_poll, m.BMS_STEP, mcu._saved_odometer,
        mcu._last_save, m.ODOMETER_SAVE_PERIOD, mcu._last_cmd_time,
        mcu.chassis.command_timeout, mcu._standby_cmd_time)
    js[:lb.J_SIZE] = (
        ml.over_current, ml.stalled, mr.over_current, mr.stalled, el.total, er.total,
        mcu._imu_same, status_in, 0, state_in, imu._left - 1 if noise else 0,
        mcu._imu_last is not None, 0, 0, 0, 0, 0, n, mode == 1, noise, bms is not None,
        mcu._bms_bits, mcu.estop_command,
        False,  # the watchdog flag: _target clears it in every period of a run
        mcu._speed_limited)
    flags = lb.J_FRESH
    js[flags:] = 0
    for j in fresh:
        js[flags + j] = 1
    kl.batch(kl.k, fs, js, targets, imu._arr if noise else kl.zero_rows, kl.imu,
             kl.due, kl.per, kl.hot, kl.counters, kl.vals, kl.sig, kl.scale, kl.frames,
             kl.out, kl.ids, kl.lens, kl.pidx)
    (oc_l, st_l, oc_r, st_r, el.total, er.total, mcu._imu_same, mcu.status, mcu.motion_fault,
     state, row, _, count, done, python_emit, steps, py_frames) = js[:17].tolist()
    if mode == 1:  # the smoother as after the last period done
        smoother.v, smoother.w = wound[done - 1] if done else start
    if not done:
        return 0
    (ml.omega, ml.setpoint, ml.current, ml._over_time, ml._stall_time,
     mr.omega, mr.setpoint, mr.current, mr._over_time, mr._stall_time,
     el._frac, er._frac, truth.x, truth.y, truth.yaw, truth.v, truth.w, truth.accel_x,
     truth.distance, mcu.odometer, stuck["left"], stuck["right"], mcu._bms_charge,
     mcu._bms_elapsed, mcu._imu_due) = fs[:25].tolist()
    if fresh and fresh[0] < done:
        mcu._last_cmd_time = float(fs[lb.F_LAST_CMD])
        mcu.stats["rx_frames"] += sum(1 for j in fresh if j < done)
    ml.over_current, ml.stalled = oc_l != 0, st_l != 0
    mr.over_current, mr.stalled = oc_r != 0, st_r != 0
    ml._steady = mr._steady = None
    mcu._watchdog = mcu._watchdog_ramp = False
    if mode != 1:
        smoother.reset(v, w)
    if state != mcu.state:
        mcu.state = m.RobotState(state)
    if mcu._imu_due != imu_due0:  # sampled
        s = kl.imu[6:].tolist()
        sample = ((s[0], s[1], s[2]), (s[3], s[4], s[5]))
        if noise and row + 1 < imu._left:
            zl = imu._arr[row + 1].tolist()
            gt, at, gb, ab = imu.gyro_turn_on, imu.accel_turn_on, imu.gyro_bias, imu.accel_bias
            gb[0], gb[1], gb[2] = gt[0] + zl[0], gt[1] + zl[1], gt[2] + zl[2]
            ab[0], ab[1], ab[2] = at[0] + zl[3], at[1] + zl[4], at[2] + zl[5]
            imu._left = row + 1
        imu._last = mcu._imu_last = mcu.imu_sample = sample
    clock = cast(SimClock, mcu.clock)  # the compiled loop runs on a SimClock only
    if steps:
        step = fs[lb.F_STEPS:lb.F_STEPS + 2 * steps].tolist()
        for i in range(0, 2 * steps, 2):
            bms.step(step[i], step[i + 1] / step[i])
    last = done - 1
    data = kl.out[:count].tobytes()
    ids, lens = kl.ids[:count].tolist(), kl.lens[:count].tolist()
    pidx = kl.pidx[:count].tolist()
    kl._next = float(kl.due[-1])
    final = None
    f = sent = 0
    send, counters, send_rows = mcu._send, mcu._counters, lean.send_rows
    for j in range(done):
        if j == last:
            if final is not None:  # back to the state after the run
                mcu.odometer, mcu.status, mcu.motion_fault, mcu.state = final
            if bms is not None and mcu._bms_elapsed >= m.BMS_STEP - 1e-9:
                bms.step(mcu._bms_elapsed, mcu._bms_charge / mcu._bms_elapsed)
                mcu._bms_charge = mcu._bms_elapsed = 0.0
            if (mcu.odometer != mcu._saved_odometer
                    and clock.now() - mcu._last_save >= m.ODOMETER_SAVE_PERIOD):
                mcu._save_state()
        elif py_frames >> j & 1:  # Python builds a frame of period j: its odometer and status
            if final is None:
                final = mcu.odometer, mcu.status, mcu.motion_fault, mcu.state
            mcu.odometer = float(fs[lb.F_ODO_AT + j])
            mcu.status, mcu.motion_fault, mcu.state = status_in, 0, state_in
        while f < count and pidx[f] == j:  # KernelLoop.send_frames inline
            fid = ids[f]
            if fid >= 0:
                send(fid, data[8 * f:8 * f + lens[f]])
                sent += 1
            else:
                sent += send_rows(-1 - fid, counters, send)
            f += 1
        if j == last and python_emit:
            kl._send(clock.now(), -1)
        clock.advance(dt)
    if sent:
        mcu.stats["tx_frames"] += sent
    return done


Incoming = Sequence[tuple[int, int, bytes]]  #: (period offset, frame id, data), by offset


def advance(mcu: McuParts, periods: int, incoming: Incoming,
            kernel_for_run: Callable[[], tuple[KernelLoop, int] | None]) -> None:
    """``Mcu.advance`` with frames from the upper side: each ``(k, frame_id, data)`` is
    received (``Mcu.receive``) just before period ``k`` (0 .. periods - 1), as a loop of
    ``receive`` and ``step()`` does it. The frames due before period k go through ``receive``;
    of those after it, a MotionCommand equal to the last one accepted but for its Counter (the
    same command, chassis and limits: only its watchdog time changes) is taken by the
    compiled run itself (``run``'s ``fresh``), so runs span commands; any other frame ends the
    run before its period. ``kernel_for_run``: the Mcu's compiled loop and the most periods a
    run may take now (none with a fault active, no defect hook or delayed frame), else None
    (asked before every run: a frame received may reboot the Mcu)."""
    if any(k < 0 or k >= periods for k, _, _ in incoming):
        raise ValueError(f"incoming frames must be for periods 0 .. {periods - 1}")
    if any(a[0] > b[0] for a, b in itertools.pairwise(incoming)):
        raise ValueError("incoming frames must be in period order")
    clock = cast(SimClock, mcu.clock)
    total, i, k = len(incoming), 0, 0
    while k < periods:
        while i < total and incoming[i][0] == k:
            _, frame_id, data = incoming[i]
            before = mcu._last_cmd
            mcu.receive(frame_id, data)
            _remember(mcu, frame_id, data, before)
            i += 1
        runs = kernel_for_run()
        done = 0
        if runs is not None:
            kernel, most = runs
            n, fresh, j = min(periods - k, most), [], i
            while j < total and incoming[j][0] < k + n:
                off, frame_id, data = incoming[j]
                if not _repeat(mcu, frame_id, data):
                    n = off - k  # the run stops before it; Python receives it
                    break
                fresh.append(off - k)
                j += 1
            if fresh and fresh[-1] >= n:  # repeats before a frame Python takes, same period
                fresh = [f for f in fresh if f < n]
            done = run(kernel, n, fresh)
            i += sum(1 for f in fresh if f < done)
        if not done:
            mcu.step()
            clock.advance(mcu.dt)
            done = 1
        k += done


def _remember(mcu: McuParts, frame_id: int, data: bytes, before: object) -> None:
    """After ``receive``: a MotionCommand just accepted (a new ``_last_cmd``) is the one a
    repeat must equal (payload but for the Counter, length, command, chassis)."""
    cmd = mcu._last_cmd
    if cmd is before or cmd is None:
        return
    msg = mcu.codec.message("MotionCommand")
    if frame_id != msg.frame_id:
        return
    counter = msg.signal("Counter")
    keep = ~(((1 << counter.length) - 1) << counter.start)
    mcu._repeat_of = (frame_id, len(data), int.from_bytes(data, "little") & keep, keep, cmd,
                      mcu.chassis)


def _repeat(mcu: McuParts, frame_id: int, data: bytes) -> bool:
    r = mcu._repeat_of
    return (r is not None and frame_id == r[0] and len(data) == r[1] and mcu._last_cmd is r[4]
            and mcu.chassis is r[5] and int.from_bytes(data, "little") & r[3] == r[2])
