"""The compiled packers (lowerbase.protocol.frame_kernel) against the codec and cantools, value
by value, on Intel (chassis) and Motorola (legged) messages, signed and offset signals."""

from __future__ import annotations

import random

import cantools
import numpy as np
import pytest

from lowerbase.protocol.codec import DBC_PATH, default_codec
from lowerbase.protocol.frame_kernel import encodable, pack, unpack
from lowerbase.protocol.frame_table import layout
from lowerbase.protocol.legged import LEGGED_DBC_PATH, legged_codec

CASES = [  # (codec, dbc path, message, signals, (multiplexer, value) or None)
    (default_codec, DBC_PATH, "MotionCommand", ("Linear", "Angular", "Mode", "Counter"), None),
    (default_codec, DBC_PATH, "WheelFeedback", ("Wheel", "LeftCount", "LeftVelocity",
                                                "LeftCurrent", "LeftDriverStatus", "Counter"),
     ("Wheel", 0)),
    (legged_codec, LEGGED_DBC_PATH, "HipCommand", ("Position", "Velocity", "Kp", "Kd",
                                                   "Torque"), None),
    (legged_codec, LEGGED_DBC_PATH, "CalfCommand", ("Position", "Velocity", "Kp", "Kd",
                                                    "Torque"), None),
    (legged_codec, LEGGED_DBC_PATH, "MotorReply", ("MotorId", "ThighPosition",
                                                   "ThighVelocity", "ThighTorque",
                                                   "Temperature", "Error"),
     ("MotorId", 2)),
]


def _values(msg, names, rng: random.Random) -> dict[str, float]:  # type: ignore[no-untyped-def]
    out = {}
    for name in names:
        s = msg.signal(name)
        lo, hi = s.raw_min * s.scale + s.offset, s.raw_max * s.scale + s.offset
        v = rng.uniform(lo, hi) if s.kind == "linear" else float(rng.randint(
            round(lo), round(hi)))
        out[name] = min(max(v, min(lo, hi)), max(lo, hi))
    return out


@pytest.mark.parametrize("case", CASES, ids=[c[2] for c in CASES])
def test_pack_and_unpack_agree_with_the_codec_and_cantools(case) -> None:  # type: ignore[no-untyped-def]
    make, path, name, names, mux = case
    msg = make().message(name)
    ref = cantools.database.load_file(str(path)).get_message_by_name(name)
    lay = layout(msg, names)
    rng = random.Random(7)
    out, back = np.zeros(8, np.uint8), np.zeros(len(names))
    for _ in range(300):
        values = _values(msg, names, rng)
        if mux is not None:
            values[mux[0]] = float(mux[1])
        vals = np.array([values[n] for n in names])
        assert encodable(vals, lay.sig, lay.scale)
        pack(vals, lay.sig, lay.scale, lay.big_endian, lay.length, out)
        want = msg.encode(values)
        assert bytes(out[:lay.length]) == want
        assert ref.encode(values, strict=False) == want
        assert unpack(out, lay.sig, lay.scale, lay.big_endian, lay.length, back)
        decoded = msg.decode(want)
        assert back.tolist() == [float(decoded[n]) for n in names]


def test_values_the_codec_refuses_are_not_encodable() -> None:
    msg = legged_codec().message("HipCommand")
    lay = layout(msg, ("Position", "Velocity", "Kp", "Kd", "Torque"))
    good = np.array([0.5, 1.0, 20.0, 1.0, 2.0])
    assert encodable(good, lay.sig, lay.scale)
    for i, bad in ((0, 12.6), (1, float("nan")), (2, -1.0), (3, 5.01), (4, float("inf"))):
        vals = good.copy()
        vals[i] = bad
        assert not encodable(vals, lay.sig, lay.scale), (i, bad)


def test_unpack_says_when_a_raw_value_is_out_of_range() -> None:
    msg = default_codec().message("ControlCommand")  # Command: 8 bits, raw range 1..7
    lay = layout(msg, ("Command",))
    vals = np.zeros(1)
    assert unpack(np.array([3, 0, 0, 0, 0, 0, 0, 0], np.uint8), lay.sig, lay.scale, False, 1,
                  vals) and vals[0] == 3.0
    assert not unpack(np.array([9, 0, 0, 0, 0, 0, 0, 0], np.uint8), lay.sig, lay.scale, False,
                      1, vals)
