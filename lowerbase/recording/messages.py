"""DriverCore state -> ROS1 messages without ROS: the content of ``lowerbase.driver.ros_io``.

Each builder fills the same fields with the same values as its namesake in ``ros_io`` (which
builds genpy classes and needs rospy); tests/recording compares the serialised bytes of both
for the same core state. Messages are rosbags objects of :func:`~.ros1_types.ros1_types`.
The recorder builds /battery and BMS with these; the high-rate messages it packs directly with
:mod:`.fastser`, whose bytes are tested equal to these builders' serialised by rosbags.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from lowerbase.recording.ros1_types import Ros1Types

POSE_AXES = (0, 1, 5)  #: (x, y, yaw) in nav_msgs/Odometry's 6x6 pose covariance
TWIST_AXES = (0, 5)  #: (vx, wz) in its 6x6 twist covariance


def to_ns(t: float) -> int:
    """``t`` [s] in integer nanoseconds, exact to the float's fraction also for epoch times
    (whole seconds and the fraction converted apart); clamped at 0 (ROS1 time is unsigned)."""
    if not t > 0.0:
        return 0
    sec = math.floor(t)
    return sec * 1_000_000_000 + round((t - sec) * 1e9)


def stamp_of(t: float, types: Ros1Types) -> Any:
    """ROS time of ``t`` [s] (clamped at 0: ROS1 time is unsigned)."""
    ns = to_ns(t)
    return types.message("builtin_interfaces/Time", sec=ns // 1_000_000_000,
                         nanosec=ns % 1_000_000_000)


def header(types: Ros1Types, seq: int, t: float, frame_id: str) -> Any:
    return types.message("std_msgs/Header", seq=seq, stamp=stamp_of(t, types),
                         frame_id=frame_id)


def embed_planar(cov: Sequence[float], axes: Sequence[int], unobserved: float,
                 extra: Mapping[int, float] | None = None) -> np.ndarray:
    """As ``ros_io.embed_planar``: the n x n ``cov`` at ``axes`` of a 6x6, ``unobserved`` on
    the other diagonal entries except ``extra`` (axis -> variance)."""
    n = len(axes)
    if len(cov) != n * n:
        raise ValueError(f"expected a {n}x{n} covariance, got {len(cov)} values")
    m = np.zeros(36)
    m[::7] = unobserved
    for a, ia in enumerate(axes):
        for b, ib in enumerate(axes):
            m[ia * 6 + ib] = float(cov[a * n + b])
    for axis, variance in (extra or {}).items():
        m[axis * 6 + axis] = variance
    return m


def quaternion_from_yaw(types: Ros1Types, yaw: float) -> Any:
    half = 0.5 * yaw
    return types.message("geometry_msgs/Quaternion", x=0.0, y=0.0, z=math.sin(half),
                         w=math.cos(half))


def _vector(types: Ros1Types, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return types.message("geometry_msgs/Vector3", x=float(x), y=float(y), z=float(z))


def odometry_msg(types: Ros1Types, head: Any, child_frame_id: str,
                 pose: tuple[float, float, float], twist: tuple[float, float],
                 pose_cov: Sequence[float], twist_cov: Sequence[float],
                 unobserved: float = 1e6) -> Any:
    """nav_msgs/Odometry of a planar base (``ros_io.odometry_msg``)."""
    position = types.message("geometry_msgs/Point", x=float(pose[0]), y=float(pose[1]), z=0.0)
    p = types.message("geometry_msgs/PoseWithCovariance", pose=types.message(
        "geometry_msgs/Pose", position=position, orientation=quaternion_from_yaw(types, pose[2])),
        covariance=embed_planar(pose_cov, POSE_AXES, unobserved))
    t = types.message("geometry_msgs/TwistWithCovariance", twist=types.message(
        "geometry_msgs/Twist", linear=_vector(types, twist[0]), angular=_vector(
            types, 0.0, 0.0, twist[1])),
        covariance=embed_planar(twist_cov, TWIST_AXES, unobserved,
                                extra={1: float(twist_cov[0])}))
    return types.message("nav_msgs/Odometry", header=head, child_frame_id=child_frame_id,
                         pose=p, twist=t)


def tf_from_odometry(types: Ros1Types, odom: Any) -> Any:
    """tf2_msgs/TFMessage with the transform ``odom`` carries, as tf2_ros' broadcaster
    sends it (``ros_io.transform_from_odometry``; the inner header's seq stays 0)."""
    h = odom.header
    p = odom.pose.pose.position
    transform = types.message(
        "geometry_msgs/TransformStamped",
        header=types.message("std_msgs/Header", seq=0, stamp=h.stamp, frame_id=h.frame_id),
        child_frame_id=odom.child_frame_id,
        transform=types.message("geometry_msgs/Transform", translation=_vector(
            types, p.x, p.y, p.z), rotation=odom.pose.pose.orientation))
    return types.message("tf2_msgs/TFMessage", transforms=[transform])


def imu_msg(types: Ros1Types, head: Any, gyro: Sequence[float], accel: Sequence[float],
            gyro_variance: float, accel_variance: float) -> Any:
    """sensor_msgs/Imu without orientation (``ros_io.imu_msg``)."""
    return types.message(
        "sensor_msgs/Imu", header=head,
        orientation=types.message("geometry_msgs/Quaternion", x=0.0, y=0.0, z=0.0, w=0.0),
        orientation_covariance=np.array([-1.0] + [0.0] * 8),
        angular_velocity=_vector(types, *gyro),
        angular_velocity_covariance=_diag3(gyro_variance),
        linear_acceleration=_vector(types, *accel),
        linear_acceleration_covariance=_diag3(accel_variance))


def _diag3(variance: float) -> np.ndarray:
    return np.array([variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance])


def battery_msg(types: Ros1Types, head: Any, fields: Mapping[str, float | int]) -> Any:
    """woosh_msgs/Battery from ``BmsFrameAccumulator.battery_fields()``."""
    return types.message("woosh_msgs/Battery", header=head, **fields)


def bms_msg(types: Ros1Types, head: Any, fields: Mapping[str, float | int]) -> Any:
    """woosh_msgs/BMS from ``BmsFrameAccumulator.bms_fields()``."""
    return types.message("woosh_msgs/BMS", header=head, **fields)


def robot_status_msg(types: Ros1Types, fields: Mapping[str, int | str]) -> Any:
    """woosh_msgs/RobotStatus from ``lowerbase.tasks.model.Status.fields()`` (as the tasks
    node's ``RobotStatus(**status.fields())``)."""
    return types.message("woosh_msgs/RobotStatus", **fields)


def status_code_msg(types: Ros1Types, code: int) -> Any:
    return types.message("std_msgs/UInt64", data=int(code) & 0xFFFF_FFFF_FFFF_FFFF)


def can_frame_msg(types: Ros1Types, head: Any, frame_id: int, data: bytes) -> Any:
    """can_msgs/Frame of a classic data frame (data padded to 8 bytes, dlc = its length)."""
    payload = np.zeros(8, dtype=np.uint8)
    payload[: len(data)] = np.frombuffer(data[:8], dtype=np.uint8)
    return types.message("can_msgs/Frame", header=head, id=frame_id,
                         is_rtr=False, is_extended=frame_id > 0x7FF, is_error=False,
                         dlc=min(len(data), 8), data=payload)


# -- the world's messages: the reference of fastser's world packers -----------------------------

def _planar_pose(types: Ros1Types, pose: Sequence[float]) -> Any:
    return types.message("geometry_msgs/Pose", position=types.message(
        "geometry_msgs/Point", x=float(pose[0]), y=float(pose[1]), z=0.0),
        orientation=quaternion_from_yaw(types, pose[2]))


def laser_scan_msg(types: Ros1Types, head: Any, angles: Sequence[float],
                   ranges: np.ndarray) -> Any:
    """sensor_msgs/LaserScan as ``lowerbase.world.ros_msgs.laser_scan`` fills it (no
    intensities); ``angles`` as ``fastser.laser_scan``'s."""
    names = ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
             "range_min", "range_max")
    return types.message("sensor_msgs/LaserScan", header=head,
                         **{k: float(v) for k, v in zip(names, angles, strict=True)},
                         ranges=np.asarray(ranges, dtype=np.float32),
                         intensities=np.zeros(0, dtype=np.float32))


def occupancy_grid_msg(types: Ros1Types, head: Any, load_time: Any, resolution: float,
                       origin: Sequence[float], data: np.ndarray) -> Any:
    """nav_msgs/OccupancyGrid as ``lowerbase.world.ros_msgs.grid_msg`` fills it."""
    cells = np.asarray(data, dtype=np.int8)
    info = types.message("nav_msgs/MapMetaData", map_load_time=load_time,
                         resolution=float(resolution), width=int(cells.shape[1]),
                         height=int(cells.shape[0]), origin=_planar_pose(types, origin))
    return types.message("nav_msgs/OccupancyGrid", header=head, info=info,
                         data=cells.ravel())


def pose_with_covariance_msg(types: Ros1Types, head: Any, pose: Sequence[float],
                             covariance: Sequence[float]) -> Any:
    """geometry_msgs/PoseWithCovarianceStamped (``ros_msgs.pose_with_covariance``)."""
    return types.message("geometry_msgs/PoseWithCovarianceStamped", header=head,
                         pose=types.message("geometry_msgs/PoseWithCovariance",
                                            pose=_planar_pose(types, pose),
                                            covariance=np.asarray(covariance, dtype=float)))


def pose_stamped_msg(types: Ros1Types, head: Any, pose: Sequence[float]) -> Any:
    return types.message("geometry_msgs/PoseStamped", header=head,
                         pose=_planar_pose(types, pose))


def path_msg(types: Ros1Types, head: Any, poses: Sequence[Sequence[float]]) -> Any:
    """nav_msgs/Path: each pose a PoseStamped with the path's stamp and frame, seq 0."""
    inner = types.message("std_msgs/Header", seq=0, stamp=head.stamp, frame_id=head.frame_id)
    return types.message("nav_msgs/Path", header=head,
                         poses=[pose_stamped_msg(types, inner, p) for p in poses])


def image_msg(types: Ros1Types, head: Any, encoding: str, array: np.ndarray) -> Any:
    """sensor_msgs/Image as ``ros_msgs.image`` fills it (16UC1 or rgb8, little-endian)."""
    data = np.ascontiguousarray(array, dtype="<u2" if encoding == "16UC1" else np.uint8)
    h, w = int(data.shape[0]), int(data.shape[1])
    return types.message("sensor_msgs/Image", header=head, height=h, width=w,
                         encoding=encoding, is_bigendian=0, step=data.nbytes // h if h else 0,
                         data=np.frombuffer(data.tobytes(), dtype=np.uint8))
