"""The frame half of the compiled lean period (:mod:`.lean_kernel`): the periodic frames'
due check and the hot frames' encoding by the codec's signal table (fastkernel.tables), plus
the helpers both halves share. Same arithmetic as the Python loop, see lean_kernel."""

from __future__ import annotations

import math

import numpy as np

from lowerbase.jit import compiled
from lowerbase.protocol.frame_kernel import pymax

_jit = compiled()


@_jit
def wrap32(x: int) -> int:
    return (x + 2147483648) % 4294967296 - 2147483648


@_jit
def encode(vals: np.ndarray, sig: np.ndarray, scale: np.ndarray, row: int, n: int,
           out: np.ndarray, slot: int) -> None:
    """Pack ``vals`` into ``out[slot]`` by the signal table rows ``row .. row+n`` of ``sig``
    (value index, start bit, length, linear?, raw min, raw max) and ``scale`` (scale,
    offset): the codec's rounding (half to even) and Intel bit layout."""
    payload = 0
    for j in range(row, row + n):
        v = vals[sig[j, 0]]
        if sig[j, 3]:
            off = scale[j, 1]
            raw = int(np.rint(v / scale[j, 0] if off == 0.0 else (v - off) / scale[j, 0]))
        else:
            raw = int(v)
        payload |= (raw & ((1 << sig[j, 2]) - 1)) << sig[j, 1]
    for b in range(8):
        out[slot, b] = (payload >> (8 * b)) & 0xFF


@_jit
def valid(vals: np.ndarray, sig: np.ndarray, scale: np.ndarray, row: int, n: int) -> bool:
    """Whether every signal of the frame encodes (finite, raw value in range); the Python
    encoder raises SignalRangeError otherwise, and the caller leaves the frame to it."""
    for j in range(row, row + n):
        v = vals[sig[j, 0]]
        if not math.isfinite(v):
            return False
        if sig[j, 3]:
            off = scale[j, 1]
            r = np.rint(v / scale[j, 0] if off == 0.0 else (v - off) / scale[j, 0])
        else:
            r = v
        if r < sig[j, 4] or r > sig[j, 5]:
            return False
    return True


@_jit
def emit(now: float, due: np.ndarray, period: np.ndarray, hot: np.ndarray,
         counters: np.ndarray, vals: np.ndarray, sig: np.ndarray, scale: np.ndarray,
         frames: np.ndarray, out: np.ndarray, ids: np.ndarray, lens: np.ndarray,
         at: int, step: int = 1) -> int:
    """LeanLoop._emit_due: the frames due now, in catalog order, into ``out``/``ids``/``lens``
    from slot ``at``
    (``ids`` -1 - i: periodic message i, built in Python); ``due`` ends with their minimum.
    ``hot[i]``: the first row of ``frames`` (frame id, length, first signal row, signal count,
    value base, shared counter) of message i and how many (0: not hot). Returns the frame
    count (from slot 0), or -1 (nothing changed) when a hot frame would not encode. ``step``:
    what a rolling counter advances by (0: the counter-stuck defect)."""
    edge = now + 1e-9
    count = at
    n = due.size - 1  # due[n]: the earliest of them (Mcu._next_any_due)
    for i in range(n):  # check first: a frame the codec refuses is Python's to raise
        if edge >= due[i] and hot[i, 1]:
            for f in range(hot[i, 0], hot[i, 0] + hot[i, 1]):
                base = frames[f, 4]
                vals[base] = float(counters[i])
                if not valid(vals[base:], sig, scale, frames[f, 2], frames[f, 3]):
                    return -1
    for i in range(n):
        d = due[i]
        if edge < d:
            continue
        p = period[i]
        missed = pymax(0.0, math.floor((now - d) / p)) if p != 0.0 else 0.0
        due[i] = d + (missed + 1.0) * p
        if hot[i, 1] == 0:
            ids[count] = -1 - i
            count += 1
            continue
        shared = frames[hot[i, 0], 5] != 0
        counter = counters[i]
        if shared:
            counters[i] = (counter + step) & 0xF
        for f in range(hot[i, 0], hot[i, 0] + hot[i, 1]):
            base = frames[f, 4]
            if not shared:
                counter = counters[i]
                counters[i] = (counter + step) & 0xF
            vals[base] = float(counter)
            encode(vals[base:], sig, scale, frames[f, 2], frames[f, 3], out, count)
            ids[count] = frames[f, 0]
            lens[count] = frames[f, 1]
            count += 1
    due[n] = due[:n].min()
    return count
