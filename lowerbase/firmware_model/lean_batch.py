"""A run of lean control periods in one compiled call (:func:`batch`, driven by
``fastkernel.KernelLoop.run`` for ``Mcu.advance``): :func:`.lean_kernel.period` after period,
on the simulated clock, while nothing needs Python.

The run stops before a period whose BMS is polled, whose command has timed out (the watchdog)
or whose IMU needs a new noise block, and after a period that emitted a frame Python builds
(not one of the hot ones), stepped the BMS pack, is due to save the odometer, or changed the
status word, the motion fault bits or the state (any of which can change ``Mcu._target``).
"""

from __future__ import annotations

import numpy as np

from lowerbase.firmware_model.lean_kernel import C_DT, _jit, period


@_jit
def batch(n: int, k: np.ndarray, now: float, boot_time: float, smoothed: bool,
          targets: np.ndarray, target_v: float, target_w: float,
          om_l: float, sp_l: float, cur_l: float, oc_l: bool, st_l: bool, ot_l: float,
          stt_l: float,
          om_r: float, sp_r: float, cur_r: float, oc_r: bool, st_r: bool, ot_r: float,
          stt_r: float,
          tot_l: int, fr_l: float, tot_r: int, fr_r: float,
          x: float, y: float, yaw: float, tv: float, tw: float, accel_x: float, distance: float,
          odometer: float, stuck_l: float, stuck_r: float,
          imu_due_t: float, imu_cycle: float, noise: bool, rows: np.ndarray, row: int,
          has_last: bool, imu: np.ndarray, imu_same: int,
          bms: bool, charge: float, elapsed: float, last_answer: float, bms_bits: int,
          next_poll: float, bms_step: float, saved_odometer: float, last_save: float,
          save_period: float, last_cmd_time: float, timeout: float,
          status: int, motion_fault: int, state: int, estop_command: bool, watchdog: bool,
          standby_cmd_time: float, limited: bool,
          due: np.ndarray, per: np.ndarray, hot: np.ndarray,
          counters: np.ndarray, vals: np.ndarray, sig: np.ndarray, scale: np.ndarray,
          frames: np.ndarray, out: np.ndarray, ids: np.ndarray, lens: np.ndarray,
          pidx: np.ndarray,
          ) -> tuple[float, float, float, bool, bool, float, float,
                     float, float, float, bool, bool, float, float,
                     int, float, int, float,
                     float, float, float, float, float, float, float,
                     float, float, float, float, float, int,
                     int, int, int, int, int, int, float, bool, bool]:
    """Up to ``n`` periods from ``now``, driving at ``target_v``, ``target_w`` (``smoothed``:
    at ``targets[j]`` in period j), no brake.
    Returns the state as :func:`.lean_kernel.period` does, then the frame count (``pidx``:
    each frame's period), the periods done, the next IMU noise row and due time, whether an
    IMU sample exists, and whether the last period's frames are Python's to emit."""
    dt = k[C_DT]
    count = 0
    done = 0
    python_emit = False
    for j in range(n):
        if bms and now >= next_poll:
            break
        if now - last_cmd_time > timeout:
            break
        imu_due = now >= imu_due_t
        if imu_due and noise and row < 0:
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
        python_frame = False
        for f in range(count, c):
            pidx[f] = j
            python_frame = python_frame or ids[f] < 0
        count = c
        if imu_due:
            imu_due_t += imu_cycle
            has_last = True
            if noise:
                row -= 1
        stop = (python_frame or (bms and elapsed >= bms_step - 1e-9)
                or (odometer != saved_odometer and now - last_save >= save_period)
                or status != status0 or motion_fault != fault0 or state != state0)
        now += dt
        if stop:
            break
    return (om_l, sp_l, cur_l, oc_l, st_l, ot_l, stt_l,
            om_r, sp_r, cur_r, oc_r, st_r, ot_r, stt_r,
            tot_l, fr_l, tot_r, fr_r,
            x, y, yaw, tv, tw, accel_x, distance,
            odometer, stuck_l, stuck_r, charge, elapsed, imu_same,
            status, motion_fault, state, count, done, row, imu_due_t, has_last, python_emit)
