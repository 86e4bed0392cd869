"""The legged driver's frames from the leg buses in compiled code: a batch of frames in order,
MotorReply decoded into the joint arrays, the actuator commands (the lower computer's, seen on
the shared buses) counted as :meth:`~lowerbase.legged_driver.core.LeggedDriverCore.on_frame`
counts them; the first other frame ends the call (Python handles it, then the rest)."""

from __future__ import annotations

import numpy as np

from lowerbase.jit import compiled
from lowerbase.protocol.frame_kernel import unpack

_jit = compiled()

#: ``counts``' slots: LeggedDriverCore.stats keys in this order
MOTOR_REPLY, WRONG_BUS, IGNORED, MALFORMED = range(4)
COUNT_KEYS = ("motor_reply", "wrong_bus", "ignored", "malformed")


@_jit
def frames(start: int, buses: np.ndarray, ids: np.ndarray, data: np.ndarray,
           reply_id: int, n_buses: int, body_bus: int, mux_sig: np.ndarray,
           mux_scale: np.ndarray, reply_sig: np.ndarray, reply_scale: np.ndarray,
           cmd_sig: np.ndarray, cmd_scale: np.ndarray, big_endian: bool,
           joints: np.ndarray, counts: np.ndarray) -> int:
    """Rows ``start..`` of (``buses``, ``ids``, ``data`` (n, 8)); ``joints`` (12, 5): position,
    velocity, effort, temperature, status. Reply variant m (CAN ID m + 1) is ``reply_sig[m]``
    (MotorId, position, velocity, torque, Temperature, Error), command m ``cmd_sig[m]``.
    Returns the index of the first row left to Python (``len(ids)`` when none)."""
    vals = np.empty(6)
    n_motors = reply_sig.shape[0]
    for r in range(start, ids.shape[0]):
        fid, bus = ids[r], buses[r]
        row = data[r]
        if fid == reply_id:
            unpack(row, mux_sig, mux_scale, big_endian, 8, vals)
            m = int(vals[0]) - 1
            if m < 0 or m >= n_motors or not unpack(row, reply_sig[m], reply_scale[m],
                                                   big_endian, 8, vals):
                counts[MALFORMED] += 1
                continue
            if bus < 0 or bus >= n_buses:
                counts[WRONG_BUS] += 1
                continue
            j = joints[bus * n_motors + m]
            j[0], j[1], j[2], j[3], j[4] = vals[1], vals[2], vals[3], vals[4], vals[5]
            counts[MOTOR_REPLY] += 1
        elif 1 <= fid <= cmd_sig.shape[0]:
            if not unpack(row, cmd_sig[fid - 1], cmd_scale[fid - 1], big_endian, 8, vals):
                counts[MALFORMED] += 1
            elif bus != body_bus:
                counts[WRONG_BUS] += 1
            else:
                counts[IGNORED] += 1
        else:
            return r
    return ids.shape[0]
