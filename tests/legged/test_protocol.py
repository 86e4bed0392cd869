"""legged.dbc: the compiled codec against cantools, and the MIT bit layout against an
independent port of the reference C code (pack_cmd / unpack_reply, float_to_uint /
uint_to_float of Ben Katz's motorcontrol firmware)."""

from __future__ import annotations

import math
import random
from pathlib import Path

import cantools
import pytest

from lowerbase.errors import SignalRangeError
from lowerbase.protocol.codec import Codec
from lowerbase.protocol.legged import (
    COMMAND_MESSAGES,
    LEGGED_DBC_PATH,
    T_MAX,
    Special,
    joint_address,
    joint_index,
    legged_codec,
    parse_special,
    special_frame,
)

DB = cantools.database.load_file(str(LEGGED_DBC_PATH))


def float_to_uint(x: float, x_min: float, x_max: float, bits: int) -> int:
    """The C reference: (int)((x - offset) * ((1 << bits) - 1) / span), truncating."""
    span = x_max - x_min
    return int((x - x_min) * ((1 << bits) - 1) / span)


def uint_to_float(x_int: int, x_min: float, x_max: float, bits: int) -> float:
    span = x_max - x_min
    return x_int * span / ((1 << bits) - 1) + x_min


def pack_cmd(p: int, v: int, kp: int, kd: int, t: int) -> bytes:
    """pack_cmd's byte layout from raw integers."""
    return bytes([p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (kp >> 8), kp & 0xFF,
                  kd >> 4, ((kd & 0xF) << 4) | (t >> 8), t & 0xFF])


def unpack_reply(buf: bytes) -> tuple[int, int, int, int]:
    """unpack_reply: (id, p_int, v_int, i_int)."""
    return (buf[0], (buf[1] << 8) | buf[2], (buf[3] << 4) | (buf[4] >> 4),
            ((buf[4] & 0xF) << 8) | buf[5])


def _random_values(msg: cantools.database.Message, rng: random.Random) -> dict[str, float]:
    values: dict[str, float] = {}
    mux = next((s for s in msg.signals if s.is_multiplexer), None)
    if mux is not None:
        values[mux.name] = rng.choice(sorted({k for s in msg.signals
                                              for k in (s.multiplexer_ids or ())}))
    for s in msg.signals:
        if s.is_multiplexer or (s.multiplexer_ids and values[mux.name] not in s.multiplexer_ids):
            continue
        raw_lo = math.ceil((s.minimum - s.offset) / s.scale - 1e-9)
        raw_hi = math.floor((s.maximum - s.offset) / s.scale + 1e-9)
        values[s.name] = rng.randint(raw_lo, raw_hi) * s.scale + s.offset
    return values


def test_every_message_agrees_with_cantools() -> None:
    codec = legged_codec()
    rng = random.Random(15)
    for msg in DB.messages:
        ours = codec.message(msg.frame_id)
        for _ in range(200):
            values = _random_values(msg, rng)
            data = ours.encode(values)
            assert data == DB.encode_message(msg.frame_id, values), msg.name
            assert ours.decode(data) == DB.decode_message(msg.frame_id, data,
                                                          decode_choices=False), msg.name


@pytest.mark.parametrize("motor_id", [1, 2, 3])
def test_command_layout_is_pack_cmd(motor_id: int) -> None:
    msg = legged_codec().message(COMMAND_MESSAGES[motor_id])
    t_max = T_MAX[motor_id]
    rng = random.Random(motor_id)
    for _ in range(500):
        p, v, kp, kd, t = (rng.randrange(1 << 16), *(rng.randrange(1 << 12) for _ in range(4)))
        data = pack_cmd(p, v, kp, kd, t)
        got = msg.decode(data)
        expected = {
            "Position": uint_to_float(p, -12.5, 12.5, 16),
            "Velocity": uint_to_float(v, -65.0, 65.0, 12),
            "Kp": uint_to_float(kp, 0.0, 500.0, 12),
            "Kd": uint_to_float(kd, 0.0, 5.0, 12),
            "Torque": uint_to_float(t, -t_max, t_max, 12),
        }
        for name, value in expected.items():
            assert got[name] == pytest.approx(value, rel=0, abs=1e-12), name
        # and back: the codec's encoding of the decoded values is the same payload
        assert msg.encode(got) == data


def test_encode_rounds_where_the_c_code_truncates() -> None:
    """Encoding a physical value: the codec rounds to the nearest step (cantools'
    convention), float_to_uint truncates: they differ by at most one step, and the codec's
    step is the nearer one."""
    msg = legged_codec().message("ThighCommand")
    rng = random.Random(2)
    for _ in range(1000):
        p = rng.uniform(-12.5, 12.5)
        data = msg.encode({"Position": p, "Velocity": 0.0, "Kp": 0.0, "Kd": 0.0,
                           "Torque": 0.0})
        ours = (data[0] << 8) | data[1]
        ref = float_to_uint(p, -12.5, 12.5, 16)
        assert ours - ref in (0, 1)
        assert abs(uint_to_float(ours, -12.5, 12.5, 16) - p) <= 12.5 / 65535 + 1e-12


@pytest.mark.parametrize("motor_id", [1, 2, 3])
def test_reply_layout_is_unpack_reply(motor_id: int) -> None:
    codec = legged_codec()
    prefix = {1: "Hip", 2: "Thigh", 3: "Calf"}[motor_id]
    t_max = T_MAX[motor_id]
    rng = random.Random(10 + motor_id)
    for _ in range(300):
        values = {"MotorId": motor_id,
                  f"{prefix}Position": rng.uniform(-12.5, 12.5),
                  f"{prefix}Velocity": rng.uniform(-65, 65),
                  f"{prefix}Torque": rng.uniform(-t_max, t_max),
                  "Temperature": rng.randint(-40, 215), "Error": rng.randint(0, 7)}
        data = codec.encode("MotorReply", values)
        motor, p, v, i = unpack_reply(data)
        assert motor == motor_id
        assert uint_to_float(p, -12.5, 12.5, 16) == pytest.approx(values[f"{prefix}Position"],
                                                                   abs=12.5 / 65535 + 1e-9)
        assert uint_to_float(v, -65, 65, 12) == pytest.approx(values[f"{prefix}Velocity"],
                                                               abs=65 / 4095 + 1e-9)
        assert uint_to_float(i, -t_max, t_max, 12) == pytest.approx(
            values[f"{prefix}Torque"], abs=t_max / 4095 + 1e-9)
        assert data[6] == values["Temperature"] + 40 and data[7] == values["Error"]
        name, decoded = codec.decode(0, data)
        assert name == "MotorReply" and decoded["MotorId"] == motor_id


def test_special_frames() -> None:
    assert special_frame(Special.ENTER_MOTOR_MODE).hex() == "fffffffffffffffc"
    assert special_frame(Special.EXIT_MOTOR_MODE).hex() == "fffffffffffffffd"
    assert special_frame(Special.ZERO_POSITION).hex() == "fffffffffffffffe"
    for kind in Special:
        assert parse_special(special_frame(kind)) is kind
    assert parse_special(bytes.fromhex("fffffffffffffffb")) is None
    assert parse_special(bytes.fromhex("7fffffffffffffff")) is None
    assert parse_special(b"\xff" * 7) is None
    # an ordinary command never encodes to a special frame unless every field is at its top
    msg = legged_codec().message("HipCommand")
    zero = msg.encode({"Position": 0, "Velocity": 0, "Kp": 0, "Kd": 0, "Torque": 0})
    assert parse_special(zero) is None


def test_out_of_range_command_is_refused() -> None:
    with pytest.raises(SignalRangeError, match="Torque"):
        legged_codec().encode("CalfCommand", {"Position": 0, "Velocity": 0, "Kp": 0,
                                              "Kd": 0, "Torque": 28.5})


def test_joint_addressing_round_trips() -> None:
    for i in range(12):
        assert joint_index(*joint_address(i)) == i
    with pytest.raises(ValueError):
        joint_index(4, 1)
    with pytest.raises(ValueError):
        joint_address(12)


def test_mixed_byte_orders_in_one_message_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "mixed.dbc"
    path.write_text('VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_: A\n\nBO_ 5 Mixed: 4 A\n'
                    ' SG_ Le : 0|8@1+ (1,0) [0|255] "" A\n'
                    ' SG_ Be : 23|16@0+ (1,0) [0|65535] "" A\n')
    with pytest.raises(TypeError, match="mixed byte orders"):
        Codec(path)
