"""One frame's signals as arrays, for the compiled packers of :mod:`.frame_kernel`.

A :class:`FrameLayout` holds, for the named signals of one catalog message (one multiplexer
variant), what the codec inlines in its generated code: the bit position in the payload read as
one integer (little-endian; a Motorola message's payload is read byte-reversed, as the codec
does), the width, signedness, conversion and raw range, and scale and offset. The DBC stays the
one description of the wire; this only lays it out for a kernel.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lowerbase.protocol.codec import MessageCodec

#: the ``kind`` column: how the codec converts (``SignalSpec.kind``)
KINDS = {"identity": 0, "int": 1, "linear": 2}
#: the ``sig`` columns
START, LENGTH, SIGNED, KIND, RAW_MIN, RAW_MAX = range(6)


@dataclass(frozen=True)
class FrameLayout:
    """Signals ``names`` of message ``name``, in that order."""

    name: str
    names: tuple[str, ...]
    sig: np.ndarray  #: int64 (n, 6): START, LENGTH, SIGNED, KIND, RAW_MIN, RAW_MAX
    scale: np.ndarray  #: float64 (n, 2): scale, offset
    big_endian: bool
    length: int  #: payload bytes


def layout(msg: MessageCodec, names: Sequence[str]) -> FrameLayout:
    """The layout of ``names`` in ``msg``; TypeError for what the kernels cannot pack (float
    signals, and signals wider than 63 bits: the kernels' payload is one int64)."""
    sig, scale = [], []
    for name in names:
        s = msg.signal(name)
        if s.is_float or s.length > 63:
            raise TypeError(f"{msg.name}.{name}: float signals and signals wider than 63 bits "
                            f"have no compiled packer")
        sig.append((s.start, s.length, int(s.is_signed), KINDS[s.kind], s.raw_min, s.raw_max))
        scale.append((float(s.scale), float(s.offset)))
    return FrameLayout(msg.name, tuple(names), np.array(sig, np.int64).reshape(-1, 6),
                       np.array(scale, np.float64).reshape(-1, 2), msg.big_endian, msg.length)
