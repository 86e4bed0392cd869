"""ROS1 wire bytes of the high-rate, fixed-layout messages, packed directly.

A recording writes about 1200 messages per simulated second; building rosbags message objects
and serialising them (:mod:`.messages`, :meth:`.ros1_types.Ros1Types.serialize`) cost about
25 us a message. The functions here pack the same fields with precompiled
:class:`struct.Struct` s into exactly the bytes rosbags' (and genpy's) ROS1 serialiser gives
for the message :mod:`.messages` builds from the same arguments (tests/recording/
test_fast_serialise.py checks both over randomized messages). ROS1 layout: little-endian, no
padding, ``time`` = uint32 sec + uint32 nsec, ``string`` = uint32 byte length + UTF-8, ``bool``
= one byte, fixed arrays without a length, variable arrays with a uint32 count.

Out-of-range integers (seq, stamp seconds or CAN id beyond uint32) raise ``struct.error``, as
rosbags' serialiser does. Stamp seconds are ROS1's uint32 (as genpy packs them); rosbags' ROS1
store stamps with an int32 ``sec`` and cannot serialise times past 2038.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

_HEADER = struct.Struct("<III")  #: seq, stamp sec, stamp nsec (then frame_id)
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_CAN = struct.Struct("<I???B8s")  #: id, is_rtr, is_extended, is_error, dlc, data[8]
_IMU = struct.Struct("<37d")  #: orientation 4, cov 9, angular 3, cov 9, linear 3, cov 9
#: pose (position 3, orientation 4, covariance 36), twist (linear 3, angular 3, covariance 36)
_ODOM = struct.Struct("<85d")
_TRANSFORM = struct.Struct("<7d")  #: translation 3, rotation 4

_POSE_IDX = tuple(a * 6 + b for a in (0, 1, 5) for b in (0, 1, 5))  #: messages.POSE_AXES
_TWIST_IDX = tuple(a * 6 + b for a in (0, 5) for b in (0, 5))  #: messages.TWIST_AXES
_DIAG = tuple(range(0, 36, 7))
_ZERO36 = (0.0,) * 36
_ONE_TRANSFORM = _U32.pack(1)
_NS = 1_000_000_000

_strings: dict[str, bytes] = {}


def string(s: str) -> bytes:
    """A ROS1 ``string``: uint32 byte length, then the UTF-8 bytes (cached: frame ids)."""
    b = _strings.get(s)
    if b is None:
        raw = s.encode()
        b = _U32.pack(len(raw)) + raw
        if len(_strings) < 256:
            _strings[s] = b
    return b


def header(seq: int, ns: int, frame_id: str) -> bytes:
    """std_msgs/Header stamped ``ns`` (non-negative integer nanoseconds)."""
    return _HEADER.pack(seq, ns // _NS, ns % _NS) + string(frame_id)


def uint64(value: int) -> bytes:
    """std_msgs/UInt64 (``messages.status_code_msg``: ``value`` masked to 64 bits)."""
    return _U64.pack(int(value) & 0xFFFF_FFFF_FFFF_FFFF)


def can_frame(seq: int, ns: int, frame_id: str, can_id: int, data: bytes) -> bytes:
    """can_msgs/Frame of a classic data frame (``messages.can_frame_msg``)."""
    payload = bytes(data[:8])
    return header(seq, ns, frame_id) + _CAN.pack(
        can_id, False, can_id > 0x7FF, False, len(payload), payload)


def imu(seq: int, ns: int, frame_id: str, gyro: Sequence[float], accel: Sequence[float],
        gyro_variance: float, accel_variance: float) -> bytes:
    """sensor_msgs/Imu without orientation (``messages.imu_msg``)."""
    gx, gy, gz = gyro
    ax, ay, az = accel
    g, a = float(gyro_variance), float(accel_variance)
    return header(seq, ns, frame_id) + _IMU.pack(
        0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        gx, gy, gz, g, 0.0, 0.0, 0.0, g, 0.0, 0.0, 0.0, g,
        ax, ay, az, a, 0.0, 0.0, 0.0, a, 0.0, 0.0, 0.0, a)


def _embed(cov: Sequence[float], idx: tuple[int, ...], unobserved: float) -> list[float]:
    """``messages.embed_planar`` as a list: ``unobserved`` on the 6x6 diagonal, ``cov`` at
    ``idx``."""
    if len(cov) != len(idx):
        n = math.isqrt(len(idx))
        raise ValueError(f"expected a {n}x{n} covariance, got {len(cov)} values")
    m = list(_ZERO36)
    for i in _DIAG:
        m[i] = unobserved
    for i, c in zip(idx, cov, strict=True):  # lengths checked above
        m[i] = float(c)
    return m


def odometry(seq: int, ns: int, frame_id: str, child_frame_id: str,
             pose: tuple[float, float, float], twist: tuple[float, float],
             pose_cov: Sequence[float], twist_cov: Sequence[float],
             unobserved: float = 1e6) -> bytes:
    """nav_msgs/Odometry of a planar base (``messages.odometry_msg``)."""
    x, y, yaw = pose
    half = 0.5 * yaw
    unobserved = float(unobserved)
    tc = _embed(twist_cov, _TWIST_IDX, unobserved)
    tc[7] = float(twist_cov[0])  # vy: the vx variance (ros_io's extra={1: ...})
    return header(seq, ns, frame_id) + string(child_frame_id) + _ODOM.pack(
        x, y, 0.0, 0.0, 0.0, math.sin(half), math.cos(half),
        *_embed(pose_cov, _POSE_IDX, unobserved),
        twist[0], 0.0, 0.0, 0.0, 0.0, twist[1], *tc)


def tf_planar(ns: int, frame_id: str, child_frame_id: str,
              pose: tuple[float, float, float]) -> bytes:
    """tf2_msgs/TFMessage with one transform (inner header seq 0) at planar ``pose``: what
    ``messages.tf_from_odometry`` makes of the odometry at ``pose``."""
    x, y, yaw = pose
    half = 0.5 * yaw
    return _ONE_TRANSFORM + header(0, ns, frame_id) + string(child_frame_id) + \
        _TRANSFORM.pack(x, y, 0.0, 0.0, 0.0, math.sin(half), math.cos(half))
