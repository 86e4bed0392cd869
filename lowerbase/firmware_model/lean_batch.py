"""A run of lean control periods in one compiled call (:func:`batch`, driven by
``fastbatch.run`` for ``Mcu.advance``): :func:`.lean_kernel.period` after period, on the
simulated clock, while nothing needs Python.

The run stops before a period whose BMS is polled, whose command has timed out (the watchdog)
or whose IMU needs a new noise block, and after a period that is due to save the odometer or
changed the status word, the motion fault bits or the state (any of which can change
``Mcu._target``). It does not stop for the frames Python builds (StatusCode, SystemStatus,
Odometer, Heartbeat, LedState, Bms*) nor for the BMS pack step: the odometer after each period
is kept (``fs[F_ODO_AT + j]``; status and state are the run's first until its last period,
which alone may change them), and the pack steps' (elapsed, charge) pairs, for Python to build
and step after the run (nothing in a run reads the pack: the BMS frames are the last poll's).

The state goes in and out through two arrays (``fs``: floats, ``js``: integers; the slots
below), not as scalar arguments: numba's handling of ~75 scalars was half a call's cost.
"""

from __future__ import annotations

import numpy as np

from lowerbase.firmware_model.lean_kernel import C_DT, _jit, period

#: ``fs`` slots: the state (in and out) ...
(F_OM_L, F_SP_L, F_CUR_L, F_OT_L, F_STT_L, F_OM_R, F_SP_R, F_CUR_R, F_OT_R, F_STT_R, F_FR_L,
 F_FR_R, F_X, F_Y, F_YAW, F_TV, F_TW, F_ACCEL, F_DIST, F_ODO, F_STUCK_L, F_STUCK_R, F_CHARGE,
 F_ELAPSED, F_IMU_DUE) = range(25)
#: ... then what only goes in
(F_NOW, F_BOOT, F_TARGET_V, F_TARGET_W, F_IMU_CYCLE, F_LAST_ANSWER, F_NEXT_POLL, F_BMS_STEP,
 F_SAVED_ODO, F_LAST_SAVE, F_SAVE_PERIOD, F_LAST_CMD, F_TIMEOUT, F_STANDBY_CMD) = range(25, 39)
F_IN = 39  #: the slots filled before a call
#: ... then up to MAX_STEPS BMS pack steps (elapsed, charge) and the odometer after each period
F_STEPS, MAX_STEPS = 39, 4
F_ODO_AT = F_STEPS + 2 * MAX_STEPS  #: ``fs`` has F_ODO_AT + the run's most periods slots
#: ``js`` slots: the state (in and out; the flags 0/1) ...
(J_OC_L, J_ST_L, J_OC_R, J_ST_R, J_TOT_L, J_TOT_R, J_IMU_SAME, J_STATUS, J_FAULT, J_STATE,
 J_ROW, J_HAS_LAST) = range(12)
#: ... what comes out (frame count, periods done, the last period's frames are Python's, the
#: BMS pack steps, bit j: period j emitted a frame Python builds) ...
J_COUNT, J_DONE, J_PY_EMIT, J_STEPS, J_PY_FRAMES = range(12, 17)
#: ... and what only goes in
J_N, J_SMOOTHED, J_NOISE, J_BMS, J_BMS_BITS, J_ESTOP, J_WATCHDOG, J_LIMITED = range(17, 25)
J_SIZE = 25
#: then, per period j of the run, 1: the last MotionCommand again before it (its watchdog
#: time refreshed; ``fs[F_LAST_CMD]`` comes back as the last such time)
J_FRESH = J_SIZE


@_jit
def batch(k: np.ndarray, fs: np.ndarray, js: np.ndarray, targets: np.ndarray,
          rows: np.ndarray, imu: np.ndarray,
          due: np.ndarray, per: np.ndarray, hot: np.ndarray,
          counters: np.ndarray, vals: np.ndarray, sig: np.ndarray, scale: np.ndarray,
          frames: np.ndarray, out: np.ndarray, ids: np.ndarray, lens: np.ndarray,
          pidx: np.ndarray) -> None:
    """Up to ``js[J_N]`` periods from ``fs[F_NOW]``, driving at the target twist
    (``js[J_SMOOTHED]``: at ``targets[j]`` in period j), no brake; the state in ``fs``/``js``
    is replaced by the state after them (see the slots above; ``pidx``: each frame's
    period)."""
    dt = k[C_DT]
    (om_l, sp_l, cur_l, ot_l, stt_l, om_r, sp_r, cur_r, ot_r, stt_r, fr_l, fr_r,
     x, y, yaw, tv, tw, accel_x, distance, odometer, stuck_l, stuck_r, charge, elapsed,
     imu_due_t, now, boot_time, target_v, target_w, imu_cycle, last_answer, next_poll,
     bms_step, saved_odometer, last_save, save_period, last_cmd_time, timeout,
     standby_cmd_time) = (
        fs[0], fs[1], fs[2], fs[3], fs[4], fs[5], fs[6], fs[7], fs[8], fs[9], fs[10], fs[11],
        fs[12], fs[13], fs[14], fs[15], fs[16], fs[17], fs[18], fs[19], fs[20], fs[21],
        fs[22], fs[23], fs[24], fs[25], fs[26], fs[27], fs[28], fs[29], fs[30], fs[31],
        fs[32], fs[33], fs[34], fs[35], fs[36], fs[37], fs[38])
    oc_l, st_l = js[J_OC_L] != 0, js[J_ST_L] != 0
    oc_r, st_r = js[J_OC_R] != 0, js[J_ST_R] != 0
    tot_l, tot_r, imu_same = js[J_TOT_L], js[J_TOT_R], js[J_IMU_SAME]
    status, motion_fault, state = js[J_STATUS], js[J_FAULT], js[J_STATE]
    row, has_last = js[J_ROW], js[J_HAS_LAST] != 0
    n, smoothed, noise, bms = js[J_N], js[J_SMOOTHED] != 0, js[J_NOISE] != 0, js[J_BMS] != 0
    bms_bits, estop_command = js[J_BMS_BITS], js[J_ESTOP] != 0
    watchdog, limited = js[J_WATCHDOG] != 0, js[J_LIMITED] != 0
    count = 0
    done = 0
    python_emit = False
    steps = 0
    py_frames = 0
    for j in range(n):
        if bms and now >= next_poll:
            break
        imu_due = now >= imu_due_t
        if imu_due and noise and row < 0:
            break
        if js[J_FRESH + j]:  # the last MotionCommand again, received before this period
            last_cmd_time = now
        if now - last_cmd_time > timeout:
            break
        z = rows[row] if imu_due and noise else rows[0]
        t_v = targets[j, 0] if smoothed else target_v
        t_w = targets[j, 1] if smoothed else target_w
        emit_now = now + 1e-9 >= due[due.size - 1]
        status0, fault0, state0 = status, motion_fault, state
        (om_l, sp_l, cur_l, oc_l, st_l, ot_l, stt_l,
         om_r, sp_r, cur_r, oc_r, st_r, ot_r, stt_r,
         tot_l, fr_l, tot_r, fr_r,
         x, y, yaw, tv, tw, accel_x, distance,
         odometer, stuck_l, stuck_r, charge, elapsed, imu_same,
         status, motion_fault, state, c) = period(
            k, now, boot_time, t_v, t_w, False,
            om_l, sp_l, cur_l, oc_l, st_l, ot_l, stt_l,
            om_r, sp_r, cur_r, oc_r, st_r, ot_r, stt_r,
            tot_l, fr_l, tot_r, fr_r, x, y, yaw, tv, tw, distance, odometer, stuck_l, stuck_r,
            imu_due, noise, z, has_last, imu, imu_same,
            bms, charge, elapsed, last_answer, bms_bits,
            status, motion_fault, state, estop_command, watchdog, standby_cmd_time, limited,
            emit_now, due, per, hot, counters, vals, sig, scale, frames,
            out, ids, lens, count)
        done = j + 1
        if c < 0:
            python_emit = True
            break
        for f in range(count, c):
            pidx[f] = j
            if ids[f] < 0:
                py_frames |= 1 << j
        count = c
        fs[F_ODO_AT + j] = odometer
        if bms and elapsed >= bms_step - 1e-9:  # the pack's step, for Python after the run
            fs[F_STEPS + 2 * steps] = elapsed
            fs[F_STEPS + 2 * steps + 1] = charge
            steps += 1
            charge = elapsed = 0.0
        if imu_due:
            imu_due_t += imu_cycle
            has_last = True
            if noise:
                row -= 1
        # room left in ``out`` for one more period with every message due, else stop
        stop = (count + frames.shape[0] + due.size > out.shape[0] or steps == MAX_STEPS
                or (odometer != saved_odometer and now - last_save >= save_period)
                or status != status0 or motion_fault != fault0 or state != state0)
        now += dt
        if stop:
            break
    fs[0], fs[1], fs[2], fs[3], fs[4] = om_l, sp_l, cur_l, ot_l, stt_l
    fs[5], fs[6], fs[7], fs[8], fs[9] = om_r, sp_r, cur_r, ot_r, stt_r
    fs[10], fs[11], fs[12], fs[13], fs[14] = fr_l, fr_r, x, y, yaw
    fs[15], fs[16], fs[17], fs[18], fs[19] = tv, tw, accel_x, distance, odometer
    fs[20], fs[21], fs[22], fs[23], fs[24] = stuck_l, stuck_r, charge, elapsed, imu_due_t
    fs[F_LAST_CMD] = last_cmd_time
    js[J_OC_L], js[J_ST_L], js[J_OC_R], js[J_ST_R] = oc_l, st_l, oc_r, st_r
    js[J_TOT_L], js[J_TOT_R], js[J_IMU_SAME] = tot_l, tot_r, imu_same
    js[J_STATUS], js[J_FAULT], js[J_STATE] = status, motion_fault, state
    js[J_ROW], js[J_HAS_LAST] = row, has_last
    js[J_COUNT], js[J_DONE], js[J_PY_EMIT] = count, done, python_emit
    js[J_STEPS], js[J_PY_FRAMES] = steps, py_frames
