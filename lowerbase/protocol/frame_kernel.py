"""Compiled packing and unpacking of one frame by its :class:`~.frame_table.FrameLayout`
(``sig``, ``scale``): the codec's arithmetic (``round((v - offset) / scale)``, half to even, to
encode; ``raw * scale + offset`` to decode), for kernels that handle many frames per call.
Tests hold both to the codec, value by value. Also the kernels' ``min``/``max`` with Python's
semantics (:func:`pymax`, :func:`pymin`, :func:`clip`), with which values are clamped before
packing."""

from __future__ import annotations

import numpy as np

from lowerbase.jit import compiled

_jit = compiled()


@_jit
def pymax(a: float, b: float) -> float:
    """Python's ``max(a, b)``: the first unless the second is greater (NaN passes as Python
    passes it)."""
    return b if b > a else a


@_jit
def pymin(a: float, b: float) -> float:
    """Python's ``min(a, b)``: the first unless the second is smaller."""
    return b if b < a else a


@_jit
def clip(value: float, lo: float, hi: float) -> float:
    """``value`` within [lo, hi] (Python's ``min(max(value, lo), hi)``; NaN passes)."""
    return lo if value < lo else hi if value > hi else value


@_jit
def raw_of(v: float, kind: int, scale: float, offset: float) -> float:
    """The raw value ``v`` encodes to (as a float: NaN for NaN)."""
    if kind == 0:
        return np.rint(v)
    if offset == 0.0:
        return np.rint(v / scale)
    return np.rint((v - offset) / scale)


@_jit
def encodable(vals: np.ndarray, sig: np.ndarray, scale: np.ndarray) -> bool:
    """Whether every value is finite and encodes within its signal's raw range (else the
    codec raises; the caller lets it)."""
    for j in range(sig.shape[0]):
        r = raw_of(vals[j], sig[j, 3], scale[j, 0], scale[j, 1])
        if not r >= sig[j, 4] or not r <= sig[j, 5]:  # NaN fails both
            return False
    return True


@_jit
def pack(vals: np.ndarray, sig: np.ndarray, scale: np.ndarray, big_endian: bool, length: int,
         out: np.ndarray) -> None:
    """``vals`` (checked by :func:`encodable`) into the payload ``out[:length]``; the bytes no
    signal covers are zero."""
    payload = 0
    for j in range(sig.shape[0]):
        raw = int(raw_of(vals[j], sig[j, 3], scale[j, 0], scale[j, 1]))
        payload |= (raw & ((1 << sig[j, 1]) - 1)) << sig[j, 0]
    for b in range(length):
        byte = (payload >> (8 * b)) & 0xFF
        out[length - 1 - b if big_endian else b] = byte


@_jit
def unpack(data: np.ndarray, sig: np.ndarray, scale: np.ndarray, big_endian: bool,
           length: int, vals: np.ndarray) -> bool:
    """The payload ``data[:length]`` into ``vals``; False when a raw value is outside its
    signal's range (the codec's strict decode raises then)."""
    payload = 0
    for b in range(length):
        payload |= int(data[length - 1 - b if big_endian else b]) << (8 * b)
    ok = True
    for j in range(sig.shape[0]):
        width = sig[j, 1]
        raw = (payload >> sig[j, 0]) & ((1 << width) - 1)
        if sig[j, 2] and raw >= 1 << (width - 1):
            raw -= 1 << width
        if raw < sig[j, 4] or raw > sig[j, 5]:
            ok = False
        vals[j] = raw if sig[j, 3] == 0 else scale[j, 0] * raw + scale[j, 1]
    return ok
