"""fastser packs exactly the ROS1 bytes of rosbags' serialiser (and genpy's, where importable)
for the messages lowerbase.recording.messages builds from the same arguments."""

from __future__ import annotations

import io
import math
import random
import struct
from typing import Any

import numpy as np
import pytest

from lowerbase.recording import fastser as fs
from lowerbase.recording import messages as m
from lowerbase.recording.ros1_types import Ros1Types, ros1_types

U32_MAX = 2**32 - 1
#: rosbags' ROS1 store stamps with builtin_interfaces/Time, whose sec is an int32: it cannot
#: serialise seconds past 2**31 - 1 (2038), which ROS1 (uint32, genpy) can; fastser can
I32_MAX = 2**31 - 1
N = 300  #: randomized messages per type


def _rng(name: str) -> random.Random:
    return random.Random(f"fastser-{name}")


def _float(rng: random.Random) -> float:
    kind = rng.random()
    if kind < 0.05:
        return rng.choice([0.0, -0.0, math.inf, -math.inf, 5e-324, 1.7976931348623157e308])
    if kind < 0.5:
        return rng.uniform(-10.0, 10.0)
    return rng.uniform(-1.0, 1.0) * 10.0 ** rng.randint(-300, 300)


def _string(rng: random.Random) -> str:
    alphabet = "abcxyz_/019" + "éß漢\U0001F916"  # multi-byte UTF-8 too
    return "".join(rng.choice(alphabet) for _ in range(rng.choice([0, 1, 3, 4, 5, 17, 64])))


def _seq(rng: random.Random) -> int:
    return rng.choice([0, 1, U32_MAX, rng.randint(0, U32_MAX)])


def _ns(rng: random.Random, sec_max: int = I32_MAX) -> int:
    sec = rng.choice([0, 1, sec_max, rng.randint(0, sec_max)])
    return sec * 1_000_000_000 + rng.choice([0, 1, 999_999_999, rng.randint(0, 999_999_999)])


def _header(types: Ros1Types, seq: int, ns: int, frame_id: str) -> Any:
    stamp = types.message("builtin_interfaces/Time", sec=ns // 1_000_000_000,
                          nanosec=ns % 1_000_000_000)
    return types.message("std_msgs/Header", seq=seq, stamp=stamp, frame_id=frame_id)


def _genpy(types: Ros1Types, name: str) -> Any:
    """A genpy class of ``name`` generated from the schema the recording carries, or None."""
    try:
        from genpy.dynamic import generate_dynamic
    except ImportError:
        return None
    return generate_dynamic(name, types.schema(name).text)[name]


def _genpy_bytes(cls: Any, data: bytes) -> bytes:
    """genpy's serialisation of ``data`` decoded by genpy: the same bytes iff the layouts
    agree field for field."""
    msg = cls()
    msg.deserialize(data)
    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()


@pytest.fixture(scope="module")
def types() -> Ros1Types:
    return ros1_types()


def test_odometry(types: Ros1Types) -> None:
    rng, cls = _rng("odom"), _genpy(types, "nav_msgs/Odometry")
    for _ in range(N):
        seq, ns, frame, child = _seq(rng), _ns(rng), _string(rng), _string(rng)
        pose = (_float(rng), _float(rng), rng.uniform(-10, 10))
        twist = (_float(rng), _float(rng))
        pc, tc = [_float(rng) for _ in range(9)], [_float(rng) for _ in range(4)]
        unobserved = rng.choice([0.0, 1e6, _float(rng)])
        ref = m.odometry_msg(types, _header(types, seq, ns, frame), child, pose, twist, pc, tc,
                             unobserved)
        fast = fs.odometry(seq, ns, frame, child, pose, twist, pc, tc, unobserved)
        assert fast == types.serialize(ref)
        if cls is not None:
            assert _genpy_bytes(cls, fast) == fast
        # the transform tf2_ros would send for it
        assert fs.tf_planar(ns, frame, child, pose) == types.serialize(
            m.tf_from_odometry(types, ref))


def test_odometry_numpy_inputs_as_the_ekf_gives_them(types: Ros1Types) -> None:
    rng = _rng("odom-np")
    for _ in range(50):
        pose = tuple(np.float64(rng.uniform(-5, 5)) for _ in range(3))
        cov = np.array([[rng.uniform(0, 1) for _ in range(3)] for _ in range(3)])
        tcov = np.array([[rng.uniform(0, 1) for _ in range(2)] for _ in range(2)])
        ref = m.odometry_msg(types, _header(types, 7, 12_500_000_000, "odom"), "base_link",
                             pose, (np.float64(0.5), np.float64(-0.2)),
                             [float(v) for v in cov.ravel()],
                             [float(v) for v in tcov.ravel()], 1e6)
        fast = fs.odometry(7, 12_500_000_000, "odom", "base_link", pose,
                           (np.float64(0.5), np.float64(-0.2)), cov.ravel().tolist(),
                           tcov.ravel().tolist(), 1e6)
        assert fast == types.serialize(ref)


def test_odometry_wrong_covariance_size_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="3x3"):
        fs.odometry(1, 0, "odom", "base_link", (0.0, 0.0, 0.0), (0.0, 0.0), [0.0] * 4,
                    [0.0] * 4)


def test_tf_message(types: Ros1Types) -> None:
    cls = _genpy(types, "tf2_msgs/TFMessage")
    rng = _rng("tf")
    for _ in range(N):
        ns, frame, child = _ns(rng), _string(rng), _string(rng)
        pose = (_float(rng), _float(rng), rng.uniform(-10, 10))
        fast = fs.tf_planar(ns, frame, child, pose)
        odom = m.odometry_msg(types, _header(types, _seq(rng), ns, frame), child, pose,
                              (0.0, 0.0), [0.0] * 9, [0.0] * 4)
        assert fast == types.serialize(m.tf_from_odometry(types, odom))
        if cls is not None:
            assert _genpy_bytes(cls, fast) == fast


def test_imu(types: Ros1Types) -> None:
    cls = _genpy(types, "sensor_msgs/Imu")
    rng = _rng("imu")
    for _ in range(N):
        seq, ns, frame = _seq(rng), _ns(rng), _string(rng)
        gyro = [_float(rng) for _ in range(3)]
        accel = [_float(rng) for _ in range(3)]
        gv, av = _float(rng), _float(rng)
        fast = fs.imu(seq, ns, frame, gyro, accel, gv, av)
        ref = m.imu_msg(types, _header(types, seq, ns, frame), gyro, accel, gv, av)
        assert fast == types.serialize(ref)
        if cls is not None:
            assert _genpy_bytes(cls, fast) == fast


def test_can_frame(types: Ros1Types) -> None:
    cls = _genpy(types, "can_msgs/Frame")
    rng = _rng("can")
    for _ in range(N):
        seq, ns, frame = _seq(rng), _ns(rng), _string(rng)
        can_id = rng.choice([0, 0x7FF, 0x800, 0x1FFFFFFF, rng.randint(0, 0x1FFFFFFF)])
        data = bytes(rng.randrange(256) for _ in range(rng.randint(0, 12)))  # > 8: cut
        fast = fs.can_frame(seq, ns, frame, can_id, data)
        ref = m.can_frame_msg(types, _header(types, seq, ns, frame), can_id, data)
        assert fast == types.serialize(ref)
        if cls is not None:
            assert _genpy_bytes(cls, fast) == fast
        msg = types.deserialize(fast, "can_msgs/Frame")
        assert (msg.dlc, bytes(msg.data[:msg.dlc]), msg.is_extended) == (
            min(len(data), 8), data[:8], can_id > 0x7FF)


def test_uint64(types: Ros1Types) -> None:
    rng = _rng("u64")
    for value in [0, 1, 2**64 - 1, 2**64, -1, *(rng.randint(-2**70, 2**70) for _ in range(N))]:
        fast = fs.uint64(value)
        assert fast == types.serialize(m.status_code_msg(types, value))
        assert types.deserialize(fast, "std_msgs/UInt64").data == value % 2**64


def test_header_fields_round_trip(types: Ros1Types) -> None:
    """The header read back by rosbags has the seq, stamp and frame id given."""
    rng = _rng("header")
    for _ in range(N):
        seq, ns, frame = _seq(rng), _ns(rng), _string(rng)
        head = types.deserialize(fs.header(seq, ns, frame), "std_msgs/Header")
        assert (head.seq, head.stamp.sec * 1_000_000_000 + head.stamp.nanosec,
                head.frame_id) == (seq, ns, frame)


def test_header_equals_genpy_over_the_full_uint32_stamp() -> None:
    """genpy (ROS1's own serialiser): the same bytes for a header built from the same fields,
    also for stamps past 2038 (where rosbags' int32 sec fails)."""
    pytest.importorskip("genpy")
    std_msgs = pytest.importorskip("std_msgs.msg")
    import genpy

    rng = _rng("header-genpy")
    for _ in range(N):
        seq, ns, frame = _seq(rng), _ns(rng, U32_MAX), _string(rng)
        ref = std_msgs.Header(seq=seq, stamp=genpy.Time(ns // 10**9, ns % 10**9),
                              frame_id=frame)
        buf = io.BytesIO()
        ref.serialize(buf)
        assert fs.header(seq, ns, frame) == buf.getvalue()


@pytest.mark.parametrize("seq, ns", [(U32_MAX + 1, 0), (-1, 0), (0, (U32_MAX + 1) * 10**9)])
def test_out_of_range_header_fails_as_rosbags_does(types: Ros1Types, seq: int,
                                                   ns: int) -> None:
    with pytest.raises(struct.error):
        fs.header(seq, ns, "odom")
    with pytest.raises(struct.error):
        types.serialize(_header(types, seq, ns, "odom"))


def test_string_cache_is_bounded() -> None:
    for i in range(1000):
        assert fs.string(f"frame{i}") == struct.pack("<I", len(f"frame{i}")) + \
            f"frame{i}".encode()
    assert len(fs._strings) <= 256
