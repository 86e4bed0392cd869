"""The legged lower computer's 1 ms period in compiled code: the 12 actuators' physics
(:class:`~lowerbase.legged.actuator.ActuatorBank`), the body controller's joint targets and
loads (feet, inverse kinematics, gravity torques: :meth:`lowerbase.legged.body.Body.step`) and
the actuator traffic's 24 frames (:meth:`lowerbase.legged.lower.LeggedLower.step`).

The kinematics are gait.py's arithmetic, operation for operation (``leg_ik``, ``leg_fk``,
``Trot.foot``, ``smoothstep``), and Python's ``min``/``max`` semantics are kept (NaN passes
through, as it does there); tests hold the kernels to those functions. The actuators' impedance
law (:func:`mit_torque`) and thermal update are defined here only: :class:`~lowerbase.legged.
actuator.Actuator` steps through them too. The state lives in the bank's arrays, so nothing
is copied in or out."""

from __future__ import annotations

import math

import numpy as np

from lowerbase.jit import compiled
from lowerbase.legged.gait import FRONT, SIDES, Trot
from lowerbase.protocol.frame_kernel import clip, encodable, pack, pymax, pymin

_jit = compiled()

# ActuatorBank.par's columns (one row per actuator)
INERTIA, DAMPING, RESISTANCE, KT_GEAR, R_THERMAL, TAU_THERMAL, TORQUE_MAX, DERATE_C, \
    FAULT_C, CLEAR_C = range(10)
N_PAR = 10
#: the kernel's answers besides 0 (done): the leg's IK failed (``bad`` holds the foot)
INSIDE_OFFSET, OUT_OF_REACH = 1, 2
OFFSETS = Trot.OFFSETS
HAND = 1e-6  #: body._gravity_torques' finite-difference step [rad]


@_jit
def smoothstep(u: float) -> float:
    u = pymin(pymax(u, 0.0), 1.0)
    return 0.5 - 0.5 * math.cos(math.pi * u)


@_jit
def torque_limit(temperature: float, par: np.ndarray) -> float:
    if temperature <= par[DERATE_C]:
        return par[TORQUE_MAX]
    frac = (par[FAULT_C] - temperature) / (par[FAULT_C] - par[DERATE_C])
    return par[TORQUE_MAX] * (0.5 + 0.5 * pymin(pymax(frac, 0.0), 1.0))


@_jit
def mit_torque(p: float, v: float, p_des: float, v_des: float, kp: float, kd: float,
               tau_ff: float, limit: float) -> float:
    """The MIT impedance law, saturated to +-limit."""
    tau = kp * (p_des - p) + kd * (v_des - v) + tau_ff
    return pymin(pymax(tau, -limit), limit)


@_jit
def actuator_step(i: int, dt: float, external: float, position: np.ndarray,
                  velocity: np.ndarray, torque: np.ndarray, temperature: np.ndarray,
                  zero: np.ndarray, mode: np.ndarray, error: np.ndarray, command: np.ndarray,
                  par: np.ndarray, ambient: np.ndarray) -> float:
    """Actuator ``i`` by ``dt`` (Actuator.step); returns its copper loss 3/2 R i_q^2 [W]."""
    p = par[i]
    if mode[i]:
        c = command[i]
        torque[i] = mit_torque(position[i] - zero[i], velocity[i], c[0], c[1], c[2], c[3],
                               c[4], torque_limit(temperature[i], p))
    else:
        torque[i] = 0.0
    accel = (torque[i] + external - p[DAMPING] * velocity[i]) / p[INERTIA]
    velocity[i] += accel * dt
    position[i] += velocity[i] * dt
    i_q = torque[i] / p[KT_GEAR]
    loss = 1.5 * p[RESISTANCE] * i_q * i_q
    steady = ambient[i] + loss * p[R_THERMAL]
    temperature[i] = steady + (temperature[i] - steady) * math.exp(-dt / p[TAU_THERMAL])
    if temperature[i] >= p[FAULT_C] and error[i] == 0:
        error[i] = 1  # ActuatorError.MOTOR_OVER_TEMPERATURE
        mode[i] = False
    return loss


@_jit
def fk_z(q0: float, q1: float, q2: float, side: float, geo: np.ndarray) -> float:
    """leg_fk's z (geo: abad_link, thigh, calf, hip_x, hip_y)."""
    zs = -geo[1] * math.cos(q1) - geo[2] * math.cos(q1 + q2)
    ys = side * geo[0]
    c, s = math.cos(q0), math.sin(q0)
    return ys * s + zs * c


@_jit
def wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@_jit
def ik(x: float, y: float, z: float, side: float, geo: np.ndarray, q: np.ndarray) -> int:
    """leg_ik into ``q``; 0, or INSIDE_OFFSET / OUT_OF_REACH."""
    r2 = y * y + z * z - geo[0] ** 2
    if r2 <= 0.0:
        return INSIDE_OFFSET
    d = math.sqrt(r2)
    q[0] = wrap(math.atan2(z, y) - math.atan2(-d, side * geo[0]))
    c2 = (x * x + r2 - geo[1] ** 2 - geo[2] ** 2) / (2 * geo[1] * geo[2])
    if not -1.0 <= c2 <= 1.0:
        return OUT_OF_REACH
    q[2] = math.acos(c2)
    q[1] = wrap(math.atan2(x, -d)
                - math.atan2(-geo[2] * math.sin(q[2]), -(geo[1] + geo[2] * math.cos(q[2]))))
    return 0


@_jit
def legs(dt: float, walking: bool, held: bool, gait_t: float, vx: float, vy: float,
         wz: float, height: float, sit_height: float, mass_g: float, kp: float, kd: float,
         geo: np.ndarray, trot: np.ndarray, stance: np.ndarray, bad: np.ndarray,
         position: np.ndarray, velocity: np.ndarray, torque: np.ndarray,
         temperature: np.ndarray, zero: np.ndarray, mode: np.ndarray, error: np.ndarray,
         command: np.ndarray, par: np.ndarray, ambient: np.ndarray, power: np.ndarray) -> int:
    """Body.step after its state machine: the feet (trotting or below the hips), their joint
    targets and gravity loads, the commands (``held``) and the 12 actuators' step; ``power``
    gets the copper loss and the electrical sum (tau w + loss) over the actuators. Returns 0,
    or (leg + 1) * 4 + INSIDE_OFFSET / OUT_OF_REACH with the foot in ``bad``: nothing of that
    leg and after it was stepped."""
    feet = np.empty((4, 3))
    period, lift = trot[0], trot[1]
    for leg in range(4):
        if walking:
            hx, hy = FRONT[leg] * geo[3], SIDES[leg] * geo[4]
            ux, uy = vx - wz * hy, vy + wz * hx
            phase = (gait_t / period + OFFSETS[leg]) % 1.0
            half = period / 2
            if phase < 0.5:
                ts = phase * period - half / 2
                feet[leg, 0], feet[leg, 1], feet[leg, 2] = -ux * ts, -uy * ts, -height
                stance[leg] = True
            else:
                u = (phase - 0.5) * 2
                k = smoothstep(u) - 0.5
                feet[leg, 0], feet[leg, 1] = ux * half * k, uy * half * k
                feet[leg, 2] = -height + lift * math.sin(math.pi * u)
                stance[leg] = False
        else:
            feet[leg, 0], feet[leg, 1], feet[leg, 2] = 0.0, 0.0, -height
            stance[leg] = True
    n_stance = 0
    for leg in range(4):
        n_stance += 1 if stance[leg] else 0
    weight = mass_g / max(n_stance, 1) if height > sit_height + 1e-9 else 0.0
    loaded = held or height > sit_height
    q = np.empty(3)
    qq = np.empty(3)
    loads = np.empty(3)
    loss_sum = 0.0
    electric = 0.0
    for leg in range(4):
        side = SIDES[leg]
        x, y, z = feet[leg, 0], side * geo[0] + feet[leg, 1], feet[leg, 2]
        fail = ik(x, y, z, side, geo, q)
        if fail:
            bad[0], bad[1], bad[2] = x, y, z
            return (leg + 1) * 4 + fail
        force = weight if stance[leg] else 0.0
        if force == 0.0:
            loads[:] = 0.0
        else:
            base = fk_z(q[0], q[1], q[2], side, geo)
            for j in range(3):
                qq[:] = q
                qq[j] += HAND
                loads[j] = -force * ((fk_z(qq[0], qq[1], qq[2], side, geo) - base) / HAND)
        for j in range(3):
            i = leg * 3 + j
            if held and mode[i]:
                command[i, 0], command[i, 1], command[i, 2] = q[j], 0.0, kp
                command[i, 3], command[i, 4] = kd, -loads[j]
            loss = actuator_step(i, dt, loads[j] if loaded else 0.0, position, velocity,
                                 torque, temperature, zero, mode, error, command, par, ambient)
            loss_sum += loss
            electric += torque[i] * velocity[i] + loss
    power[0], power[1] = loss_sum, electric
    return 0


@_jit
def reply(i: int, position: np.ndarray, zero: np.ndarray, velocity: np.ndarray,
          torque: np.ndarray, temperature: np.ndarray, error: np.ndarray,
          reply_sig: np.ndarray, reply_scale: np.ndarray, limits: np.ndarray,
          big_endian: bool, row: np.ndarray, vals: np.ndarray) -> bool:
    """Actuator ``i``'s MotorReply into ``row`` (False, nothing written: it does not encode);
    ``vals``: scratch of 6."""
    m = i % 3
    t_max = limits[4 + m]
    vals[0] = m + 1
    vals[1] = clip(position[i] - zero[i], -limits[0], limits[0])
    vals[2] = clip(velocity[i], -limits[1], limits[1])
    vals[3] = clip(torque[i], -t_max, t_max)
    vals[4] = np.rint(clip(temperature[i], -40.0, 215.0))
    vals[5] = error[i]
    if not encodable(vals, reply_sig[m], reply_scale[m]):
        return False
    pack(vals, reply_sig[m], reply_scale[m], big_endian, 8, row)
    return True


@_jit
def traffic(special: int, position: np.ndarray, zero: np.ndarray, velocity: np.ndarray,
            torque: np.ndarray, temperature: np.ndarray, error: np.ndarray, mode: np.ndarray,
            command: np.ndarray, cmd_sig: np.ndarray, cmd_scale: np.ndarray,
            reply_sig: np.ndarray, reply_scale: np.ndarray, limits: np.ndarray,
            big_endian: bool, out: np.ndarray) -> int:
    """The period's actuator traffic into ``out`` (24, 8): per joint its command (the special
    frame ``special`` when > 0, the body's MIT command in motor mode, zero gains outside it)
    and its reply. ``limits``: P_MAX, V_MAX, KP_MAX, KD_MAX, then T_MAX of CAN IDs 1..3.
    Returns -1, or the first frame whose values do not encode (nothing from it on is
    written)."""
    vals = np.empty(6)
    p_max, v_max, kp_max, kd_max = limits[0], limits[1], limits[2], limits[3]
    for i in range(position.shape[0]):
        m = i % 3
        t_max = limits[4 + m]
        reported = position[i] - zero[i]
        row = out[2 * i]
        if special > 0:
            row[:7] = 0xFF
            row[7] = special
        else:
            if mode[i]:
                c = command[i]
                vals[0], vals[1] = clip(c[0], -p_max, p_max), clip(c[1], -v_max, v_max)
                vals[2], vals[3] = clip(c[2], 0.0, kp_max), clip(c[3], 0.0, kd_max)
                vals[4] = clip(c[4], -t_max, t_max)
            else:
                vals[0] = clip(reported, -p_max, p_max)
                vals[1] = vals[2] = vals[3] = vals[4] = 0.0
            if not encodable(vals[:5], cmd_sig[m], cmd_scale[m]):
                return 2 * i
            pack(vals[:5], cmd_sig[m], cmd_scale[m], big_endian, 8, row)
        if not reply(i, position, zero, velocity, torque, temperature, error, reply_sig,
                     reply_scale, limits, big_endian, out[2 * i + 1], vals):
            return 2 * i + 1
    return -1
