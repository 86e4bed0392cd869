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

import numpy as np

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


# -- the world's messages (lowerbase.recording.world) -------------------------------------------

_SCAN = struct.Struct("<7f")  #: angle_min, angle_max, increment, time_increment, scan_time,
#                               range_min, range_max
_POSE = struct.Struct("<7d")  #: position 3, orientation 4
_COV = struct.Struct("<36d")
_MAP_INFO = struct.Struct("<IIfII7d")  #: load time sec, nsec, resolution, width, height, origin


def _planar_pose(pose: Sequence[float]) -> bytes:
    x, y, yaw = pose
    half = 0.5 * yaw
    return _POSE.pack(x, y, 0.0, 0.0, 0.0, math.sin(half), math.cos(half))


def laser_scan(seq: int, ns: int, frame_id: str, angles: Sequence[float],
               ranges: np.ndarray) -> bytes:
    """sensor_msgs/LaserScan without intensities (``messages.laser_scan_msg``): ``angles`` =
    (angle_min, angle_max, angle_increment, time_increment, scan_time, range_min, range_max),
    ``ranges`` packed as little-endian float32."""
    data = np.ascontiguousarray(ranges, dtype="<f4")
    return header(seq, ns, frame_id) + _SCAN.pack(*angles) + _U32.pack(data.size) + \
        data.tobytes() + _U32.pack(0)


def occupancy_grid(seq: int, ns: int, frame_id: str, load_ns: int, resolution: float,
                   origin: Sequence[float], data: np.ndarray) -> bytes:
    """nav_msgs/OccupancyGrid (``messages.occupancy_grid_msg``): ``data`` (height, width)
    int8, row 0 first (nav_msgs' row-major order), ``origin`` a planar (x, y, yaw)."""
    cells = np.ascontiguousarray(data, dtype=np.int8)
    height, width = cells.shape
    x, y, yaw = origin
    half = 0.5 * yaw
    return header(seq, ns, frame_id) + _MAP_INFO.pack(
        load_ns // _NS, load_ns % _NS, resolution, width, height,
        x, y, 0.0, 0.0, 0.0, math.sin(half), math.cos(half)) + _U32.pack(cells.size) + \
        cells.tobytes()


def pose_with_covariance(seq: int, ns: int, frame_id: str, pose: Sequence[float],
                         covariance: Sequence[float]) -> bytes:
    """geometry_msgs/PoseWithCovarianceStamped of a planar pose, the 36 covariance values as
    given (``messages.pose_with_covariance_msg``)."""
    return header(seq, ns, frame_id) + _planar_pose(pose) + _COV.pack(*covariance)


def pose_stamped(seq: int, ns: int, frame_id: str, pose: Sequence[float]) -> bytes:
    """geometry_msgs/PoseStamped of a planar pose (``messages.pose_stamped_msg``)."""
    return header(seq, ns, frame_id) + _planar_pose(pose)


def path(seq: int, ns: int, frame_id: str, poses: Sequence[Sequence[float]]) -> bytes:
    """nav_msgs/Path of planar poses, each a PoseStamped with the path's stamp and frame and
    seq 0 (as move_base's planners fill it; ``messages.path_msg``)."""
    inner = header(0, ns, frame_id)
    return header(seq, ns, frame_id) + _U32.pack(len(poses)) + b"".join(
        inner + _planar_pose(p) for p in poses)


def image(seq: int, ns: int, frame_id: str, encoding: str, array: np.ndarray) -> bytes:
    """sensor_msgs/Image of a 16UC1 (h, w) or rgb8 (h, w, 3) array, little-endian rows
    (``messages.image_msg``)."""
    dtype = "<u2" if encoding == "16UC1" else np.uint8
    data = np.ascontiguousarray(array, dtype=dtype)
    h, w = int(data.shape[0]), int(data.shape[1])
    step = data.nbytes // h if h else 0
    return header(seq, ns, frame_id) + _U32.pack(h) + _U32.pack(w) + string(encoding) + \
        b"\x00" + _U32.pack(step) + _U32.pack(data.nbytes) + data.tobytes()
