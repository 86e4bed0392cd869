"""The compiled (numba) control period behind :class:`~.fastloop.LeanLoop`.

``period`` is :meth:`LeanLoop.step <.fastloop.LeanLoop.step>` from the target twist on (both
motors, the accel slip, the ground truth, both encoders, the odometer, the IMU sample, the BMS
current integration, the status word and state), then the due check of every periodic frame
with the hot ones (WheelFeedback x2, MotionState, ImuGyro, ImuAccel) encoded into ``out`` and
the others left as placeholders for Python to build in their place. It computes the same IEEE
expressions in the same order as the Python loop (numba without fastmath neither reorders nor
fuses them; expm1/sin/cos are the C library's, as CPython's ``math`` calls them; ``pymax`` and
``pymin`` pick what Python's ``max``/``min`` pick), so the frame trace is bit-identical
(tests/firmware_model/test_frame_trace.py, test_lean_kernel.py).

The state goes in and comes out as scalars: the Python objects (WheelMotor, EncoderCounter,
GroundTruth, Mcu) stay the one truth between periods, so anyone may read or write them.
"""

from __future__ import annotations

import math

import numpy as np

from lowerbase.firmware_model.lean_bits import (
    BMS_LINK_LOST,
    BMS_PROTECTION,
    COMMAND_IN_STANDBY,
    ESTOP_BITS,
    ESTOP_COMMAND,
    IMU_FAULT,
    L_ENC,
    L_FAULT,
    L_OVER,
    L_STALL,
    R_ENC,
    R_FAULT,
    R_OVER,
    R_STALL,
    SPEED_LIMITED,
    WATCHDOG_STOP,
)
from lowerbase.firmware_model.lean_frames import _jit, emit, wrap32
from lowerbase.protocol.frame_kernel import clip, pymax, pymin

TWO_PI = 2.0 * math.pi

# -- indices into the constants array (built by fastkernel.constants) --------------------------
#: per motor (left at 0, right at M): limit, alpha, tau, ome_zero, ome_dt, half_mass, rolling,
#: radius, min_speed, viscous, eta, ratio, torque_constant, idle, oc_limit, oc_time,
#: stall_speed, stall_time, stall_current
M = 19
#: after both motors: chassis and the rest
C_DIST, C_MIN, C_PERIM, C_RL, C_RR, C_BPP_L, C_BPP_R, C_PPR_L, C_PPR_R = range(2 * M, 2 * M + 9)
C_STALL, C_THR, C_SFRAC, C_TR_L, C_TR_R, C_TRACK, C_TOP, C_IDLE2 = range(2 * M + 9, 2 * M + 17)
C_GS, C_AS, C_GMAX, C_AMAX, C_GRAV, C_DT = range(2 * M + 17, 2 * M + 23)
_C_SPARE, C_CARRIED, C_ENC_T, C_IMU_N, C_STANDBY_T, C_LINK_T = range(2 * M + 23, 2 * M + 29)
C_GF, C_AF, C_GT, C_AT = 2 * M + 29, 2 * M + 32, 2 * M + 35, 2 * M + 38  # 3 each
#: data, not constants: the slip fractions (left, right) of the slip events in force in this
#: period (SlipModel.event_fractions), written by KernelLoop.step before the call; 0 without
C_SLIP_L, C_SLIP_R = 2 * M + 41, 2 * M + 42
#: data too (Mcu._fault_data): 1 while that encoder drops its pulses (the encoder fault), 1
#: while the IMU repeats its last sample (imu-freeze), 1 while that driver's over-current is
#: injected (the overcurrent fault: latched before the motor steps)
C_DROP_L, C_DROP_R, C_FROZEN = 2 * M + 43, 2 * M + 44, 2 * M + 45
C_OVER_L, C_OVER_R = 2 * M + 46, 2 * M + 47
#: data too: 1 while that wheel is blocked (the stall fault; WheelMotor.blocked)
C_BLOCK_L, C_BLOCK_R = 2 * M + 48, 2 * M + 49
#: data too (KernelLoop.set_hooks, from the fault hooks acting): the status bits the faults
#: assert (the button e-stop, the bus error) and the rolling counters' step (1; 0 with the
#: counter-stuck defect)
C_FAULT_BITS, C_COUNT_STEP = 2 * M + 50, 2 * M + 51
C_SIZE = 2 * M + 52
#: state numbers of RobotState
ACTIVE, EMERGENCY_STOP, FAULT, STANDBY = 2, 3, 4, 1

@_jit
def motor_step(k: np.ndarray, o: int, target: float, dt: float, brake: bool, omega: float,
               setpoint: float, over_current: bool, stalled: bool, over_time: float,
               stall_time: float, blocked: bool) -> tuple[float, float, float, float, bool,
                                                          bool, float, float]:
    """WheelMotor.step without load force (``blocked``: the stall fault's blocked wheel, not
    pressed); constants at ``k[o:]``.
    Returns (angle, omega, setpoint, current, over_current, stalled, over_time, stall_time)."""
    limit, alpha, tau, ome_zero, ome_dt = k[o], k[o + 1], k[o + 2], k[o + 3], k[o + 4]
    radius = k[o + 7]
    if brake or over_current or abs(target) * radius < k[o + 8]:
        target = 0.0
    target = pymin(pymax(target, -limit), limit)
    omega0 = omega
    r0 = target if alpha == 0.0 else setpoint
    t_ramp = 0.0 if alpha == 0.0 else pymin(dt, abs(target - r0) / alpha)
    slope = math.copysign(alpha, target - r0) if t_ramp > 0.0 else 0.0
    t = t_ramp
    if tau <= 0.0:
        omega, angle = r0 + slope * t, r0 * t + 0.5 * slope * t * t
    else:
        c = omega0 - r0 + slope * tau
        one_minus_e = -math.expm1(-t / tau) if t != 0.0 else ome_zero
        omega = r0 + slope * t - slope * tau + c * (1.0 - one_minus_e)
        angle = r0 * t + 0.5 * slope * t * t - slope * tau * t + c * tau * one_minus_e
    setpoint = target if t_ramp < dt or alpha == 0.0 else r0 + slope * t_ramp
    t = dt - t_ramp
    if tau <= 0.0:
        omega, angle2 = setpoint + 0.0 * t, setpoint * t + 0.5 * 0.0 * t * t
    else:
        c = omega - setpoint + 0.0 * tau
        one_minus_e = ome_dt if t == dt else -math.expm1(-t / tau)
        omega = setpoint + 0.0 * t - 0.0 * tau + c * (1.0 - one_minus_e)
        angle2 = setpoint * t + 0.5 * 0.0 * t * t - 0.0 * tau * t + c * tau * one_minus_e
    angle += angle2
    if blocked:  # WheelMotor._update_current, blocked: the driver's saturation when commanded
        omega, angle = 0.0, 0.0
        commanded = abs(setpoint) * radius >= k[o + 16] and not over_current
        current = math.copysign(k[o + 18], setpoint) if commanded else 0.0
        current += math.copysign(k[o + 13], current)
    else:
        wheel_accel = (omega - omega0) / dt
        v = omega * radius
        sign_v = 0.0 if v == 0.0 else math.copysign(1.0, v)
        force = k[o + 5] * wheel_accel * radius
        force += sign_v * k[o + 6] + k[o + 9] * v
        force += 0.0  # the load force
        wheel_torque = force * radius
        eta, ratio = k[o + 10], k[o + 11]
        if wheel_torque * omega >= 0.0:
            motor_torque = wheel_torque / (ratio * eta)
        else:
            motor_torque = wheel_torque * eta / ratio
        amps = motor_torque / k[o + 12]
        current = amps + math.copysign(k[o + 13], amps)
    over = abs(current) > k[o + 14]
    over_time = over_time + dt if over else 0.0
    if over and over_time >= k[o + 15]:
        over_current = True
    lagging = abs(setpoint) * radius >= k[o + 16] and abs(omega) < 0.5 * abs(setpoint)
    stall_time = stall_time + dt if lagging else 0.0
    if lagging and stall_time >= k[o + 17]:
        stalled = True
    return angle, omega, setpoint, current, over_current, stalled, over_time, stall_time


@_jit
def encoder_add(frac: float, angle: float, ppr: float) -> tuple[int, float]:
    """EncoderCounter.add (direction +1, no dropout): (pulses, new remainder)."""
    x = frac + 1.0 * angle * ppr
    n = math.floor(x)
    frac = x - n
    if frac >= 1.0:
        n, frac = n + 1, 0.0
    return n, frac


@_jit
def period(k: np.ndarray, now: float, boot_time: float, target_v: float, target_w: float,
           brake: bool,
           om_l: float, sp_l: float, cur_l: float, oc_l: bool, st_l: bool, ot_l: float,
           stt_l: float,
           om_r: float, sp_r: float, cur_r: float, oc_r: bool, st_r: bool, ot_r: float,
           stt_r: float,
           tot_l: int, fr_l: float, tot_r: int, fr_r: float,
           x: float, y: float, yaw: float, tv: float, tw: float, distance: float,
           odometer: float, stuck_l: float, stuck_r: float,
           imu_due: bool, noise: bool, z: np.ndarray, has_last: bool, imu: np.ndarray,
           imu_same: int,
           bms: bool, charge: float, elapsed: float, last_answer: float, bms_bits: int,
           status: int, motion_fault: int, state: int, estop_command: bool, watchdog: bool,
           standby_cmd_time: float, limited: bool,
           emit_now: bool, due: np.ndarray, per: np.ndarray, hot: np.ndarray,
           counters: np.ndarray, vals: np.ndarray, sig: np.ndarray, scale: np.ndarray,
           frames: np.ndarray, out: np.ndarray, ids: np.ndarray, lens: np.ndarray, at: int,
           ) -> tuple[float, float, float, bool, bool, float, float,
                      float, float, float, bool, bool, float, float,
                      int, float, int, float,
                      float, float, float, float, float, float, float,
                      float, float, float, float, float, int,
                      int, int, int, int]:
    """One lean control period after ``Mcu._target`` (see the module docstring). ``imu[6:]``
    holds the current IMU sample (gyro, accel), replaced by the new one when ``imu_due``
    (``z``: its 12 noise values). Returns the new state and, last, the frame count of
    :func:`emit` from slot ``at`` (``at`` when ``emit_now`` is False, -1 when Python must
    emit)."""
    dt = k[C_DT]
    half = 0.5 * target_w * k[C_DIST]
    v_l, v_r = target_v - half, target_v + half
    t_l = 0.0 if abs(v_l) < k[C_MIN] else v_l * 2.0 * math.pi / k[C_PERIM] * k[C_RL] / k[11]
    t_r = 0.0 if abs(v_r) < k[C_MIN] else v_r * 2.0 * math.pi / k[C_PERIM] * k[C_RR] / k[M + 11]
    if k[C_OVER_L]:  # WheelMotor.inject_over_current (Mcu._apply_faults)
        oc_l = True
    if k[C_OVER_R]:
        oc_r = True
    before_l, before_r = om_l, om_r
    bl_l, bl_r = k[C_BLOCK_L] != 0.0, k[C_BLOCK_R] != 0.0
    a_l, om_l, sp_l, cur_l, oc_l, st_l, ot_l, stt_l = motor_step(
        k, 0, t_l, dt, brake, om_l, sp_l, oc_l, st_l, ot_l, stt_l, bl_l)
    a_r, om_r, sp_r, cur_r, oc_r, st_r, ot_r, stt_r = motor_step(
        k, M, t_r, dt, brake, om_r, sp_r, oc_r, st_r, ot_r, stt_r, bl_r)
    rim_l = (om_l - before_l) / dt * k[7]
    rim_r = (om_r - before_r) / dt * k[M + 7]
    s_l, s_r = k[C_SLIP_L], k[C_SLIP_R]  # SlipModel.step: the events' fractions, then accel
    if k[C_THR] > 0.0:
        if abs(rim_l) > k[C_THR]:
            s_l = pymax(s_l, k[C_SFRAC])
        if abs(rim_r) > k[C_THR]:
            s_r = pymax(s_r, k[C_SFRAC])
    # GroundTruth.step without surroundings, integrate_pose inline
    v_left = (1.0 - s_l) * (a_l / dt) * k[C_TR_L]
    v_right = (1.0 - s_r) * (a_r / dt) * k[C_TR_R]
    v, w = 0.5 * (v_left + v_right), (v_right - v_left) / k[C_TRACK]
    h = 0.5 * w * dt
    sinc = 1.0 - h * h / 6.0 if abs(h) < 1e-4 else math.sin(h) / h
    chord = v * dt * sinc
    mid = yaw + h
    x, y, yaw = x + chord * math.cos(mid), y + chord * math.sin(mid), yaw + 2.0 * h
    accel_x = (v - tv) / dt
    tv, tw = v, w
    distance += abs(v) * dt
    moved_l, fr_l = (0, fr_l) if k[C_DROP_L] else encoder_add(fr_l, a_l, k[C_PPR_L])
    moved_r, fr_r = (0, fr_r) if k[C_DROP_R] else encoder_add(fr_r, a_r, k[C_PPR_R])
    tot_l += moved_l
    tot_r += moved_r
    ds = 0.0
    ds += 0.5 * moved_l * k[C_BPP_L]
    ds += 0.5 * moved_r * k[C_BPP_R]
    if abs(sp_l) * k[7] > k[C_STALL] and moved_l == 0 and not bl_l:  # Mcu._check_encoder
        stuck_l += dt
    else:
        stuck_l = 0.0
    if abs(sp_r) * k[M + 7] > k[C_STALL] and moved_r == 0 and not bl_r:
        stuck_r += dt
    else:
        stuck_r = 0.0
    odometer += abs(ds)
    if imu_due:
        imu_sample(k, z, noise, tv, tw, accel_x, imu)
        same = True
        if not k[C_FROZEN]:  # frozen: ImuModel.sample gives its last sample again
            for j in range(6):
                same = same and imu[j] == imu[6 + j]
                imu[6 + j] = imu[j]
        imu_same = imu_same + 1 if has_last and same else 0
    if bms:
        total = k[C_IDLE2]
        total += abs(cur_l) * (abs(om_l * k[11] * 60.0 / TWO_PI) / k[C_TOP])
        total += abs(cur_r) * (abs(om_r * k[M + 11] * 60.0 / TWO_PI) / k[C_TOP])
        charge += total * dt
        elapsed += dt
    # LeanLoop._status
    s = status & int(k[C_CARRIED])
    if estop_command:
        s |= ESTOP_COMMAND
    if watchdog:
        s |= WATCHDOG_STOP
    if now - standby_cmd_time < k[C_STANDBY_T]:
        s |= COMMAND_IN_STANDBY
    if limited:
        s |= SPEED_LIMITED
    s, motion_fault = side_bits(s, motion_fault, oc_l, st_l, stuck_l >= k[C_ENC_T],
                                L_OVER, L_STALL, L_FAULT, L_ENC)
    s, motion_fault = side_bits(s, motion_fault, oc_r, st_r, stuck_r >= k[C_ENC_T],
                                R_OVER, R_STALL, R_FAULT, R_ENC)
    s |= motion_fault
    if imu_same >= k[C_IMU_N]:
        s |= IMU_FAULT
    s |= int(k[C_FAULT_BITS])
    if bms:
        lost = now - last_answer > k[C_LINK_T]
        s |= (BMS_LINK_LOST if lost else 0) | bms_bits
    status = s
    if state == ACTIVE or state == EMERGENCY_STOP or state == FAULT:  # noqa: SIM109
        if s & ESTOP_BITS:
            state = EMERGENCY_STOP
        elif motion_fault or s & BMS_PROTECTION:
            state = FAULT
        elif state != ACTIVE:
            state = STANDBY
    count = at
    if emit_now:
        hot_values(k, vals, om_l, cur_l, oc_l, st_l, tot_l, om_r, cur_r, oc_r, st_r, tot_r, imu)
        count = emit(now, due, per, hot, counters, vals, sig, scale, frames, out, ids, lens, at,
                     int(k[C_COUNT_STEP]))
    return (om_l, sp_l, cur_l, oc_l, st_l, ot_l, stt_l,
            om_r, sp_r, cur_r, oc_r, st_r, ot_r, stt_r,
            tot_l, fr_l, tot_r, fr_r,
            x, y, yaw, tv, tw, accel_x, distance,
            odometer, stuck_l, stuck_r, charge, elapsed, imu_same,
            status, motion_fault, state, count)


@_jit
def side_bits(s: int, motion_fault: int, over_current: bool, stalled: bool, encoder: bool,
              over_bit: int, stall_bit: int, fault_bit: int, encoder_bit: int
              ) -> tuple[int, int]:
    """One side's status bits (LeanLoop._status): over-current, stall, the motor fault they
    latch (also into ``motion_fault``), the encoder fault; returns (status, motion_fault)."""
    if over_current:
        s |= over_bit
    if stalled:
        s |= stall_bit
    if over_current or stalled:
        s |= fault_bit
        motion_fault |= fault_bit
    if encoder:
        s |= encoder_bit
    return s, motion_fault


@_jit
def imu_sample(k: np.ndarray, z: np.ndarray, noise: bool, v: float, w: float, accel_x: float,
               imu: np.ndarray) -> None:
    """ImuModel.sample of GroundTruth.body_omega/body_accel, not frozen, into ``imu[:6]``."""
    o0, o1, o2 = 0.0, 0.0, w
    f0, f1, f2 = accel_x, v * w, 0.0 + k[C_GRAV]
    if noise:
        gs, as_ = k[C_GS], k[C_AS]
        g, a = C_GT, C_AT
        o0 = gs * o0 + (k[g] + z[0]) + z[6]
        o1 = gs * o1 + (k[g + 1] + z[1]) + z[7]
        o2 = gs * o2 + (k[g + 2] + z[2]) + z[8]
        f0 = as_ * f0 + (k[a] + z[3]) + z[9]
        f1 = as_ * f1 + (k[a + 1] + z[4]) + z[10]
        f2 = as_ * f2 + (k[a + 2] + z[5]) + z[11]
    g_max, a_max = k[C_GMAX], k[C_AMAX]
    imu[0] = pymin(pymax(o0 + k[C_GF], -g_max), g_max)
    imu[1] = pymin(pymax(o1 + k[C_GF + 1], -g_max), g_max)
    imu[2] = pymin(pymax(o2 + k[C_GF + 2], -g_max), g_max)
    imu[3] = pymin(pymax(f0 + k[C_AF], -a_max), a_max)
    imu[4] = pymin(pymax(f1 + k[C_AF + 1], -a_max), a_max)
    imu[5] = pymin(pymax(f2 + k[C_AF + 2], -a_max), a_max)


#: where the hot values start in ``vals`` (slot 0 of each: the Counter) and, in the constants,
#: the clip ranges: WheelFeedback left/right velocity and current, MotionState linear and
#: angular, ImuGyro and ImuAccel x, y, z (lo, hi each)
V_WF_L, V_WF_R, V_MS, V_IG, V_IA, V_SIZE = 0, 6, 12, 15, 19, 23
R_WF_L, R_WF_R, R_MS, R_IG, R_IA, R_SIZE = 0, 4, 8, 12, 18, 24


@_jit
def hot_values(k: np.ndarray, vals: np.ndarray, om_l: float, cur_l: float, oc_l: bool,
               st_l: bool, tot_l: int, om_r: float, cur_r: float, oc_r: bool, st_r: bool,
               tot_r: int, imu: np.ndarray) -> None:
    """The hot frames' values as LeanLoop's builders compute them (ranges in ``k[C_SIZE:]``)."""
    rg = k[C_SIZE:]
    vel_l = om_l * k[C_PPR_L] * k[C_BPP_L]
    vel_r = om_r * k[C_PPR_R] * k[C_BPP_R]
    vals[V_WF_L + 1] = 0.0
    vals[V_WF_L + 2] = float(wrap32(tot_l))
    vals[V_WF_L + 3] = clip(vel_l, rg[R_WF_L], rg[R_WF_L + 1])
    vals[V_WF_L + 4] = clip(cur_l, rg[R_WF_L + 2], rg[R_WF_L + 3])
    enc_l, enc_r = 4 if k[C_DROP_L] else 0, 4 if k[C_DROP_R] else 0  # EncoderCounter.status_bits
    vals[V_WF_L + 5] = float((1 if oc_l else 0) | (2 if st_l else 0) | enc_l)
    vals[V_WF_R + 1] = 1.0
    vals[V_WF_R + 2] = float(wrap32(tot_r))
    vals[V_WF_R + 3] = clip(vel_r, rg[R_WF_R], rg[R_WF_R + 1])
    vals[V_WF_R + 4] = clip(cur_r, rg[R_WF_R + 2], rg[R_WF_R + 3])
    vals[V_WF_R + 5] = float((1 if oc_r else 0) | (2 if st_r else 0) | enc_r)
    v, w = 0.5 * (vel_l + vel_r), (vel_r - vel_l) / k[C_DIST]
    vals[V_MS + 1] = clip(v, rg[R_MS], rg[R_MS + 1])
    vals[V_MS + 2] = clip(w, rg[R_MS + 2], rg[R_MS + 3])
    for j in range(3):
        vals[V_IG + 1 + j] = clip(imu[6 + j], rg[R_IG + 2 * j], rg[R_IG + 2 * j + 1])
        vals[V_IA + 1 + j] = clip(imu[9 + j], rg[R_IA + 2 * j], rg[R_IA + 2 * j + 1])
