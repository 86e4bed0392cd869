"""DriverCore state -> ROS messages, and ROS messages -> DriverCore inputs.

Small pure functions: each takes plain values (or the core's views) and a stamp and returns one
message; nothing here talks to a master. Units follow REP-103 (metres, radians, seconds, SI
rates), frames REP-105 (``odom`` -> ``base_link``). Importing this module needs rospy's message
packages (std_msgs, geometry_msgs, nav_msgs, sensor_msgs) and the generated woosh_msgs; the CLI
turns an ImportError into one :class:`~lowerbase.errors.RosUnavailableError` line.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Twist, Vector3
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64, Header, String, UInt64
from woosh_msgs.msg import BMS, LED, Battery, Information, Parameter

from lowerbase.errors import WorldError

__all__ = [
    "BMS", "LED", "ODOM_POSE", "Battery", "Float64", "Imu", "Information", "Odometry",
    "Parameter", "String", "Twist", "UInt64", "battery_msg", "bms_msg", "embed_planar",
    "imu_msg", "information_msg", "led_args", "odom_header", "odom_pose", "odom_pose_of",
    "odom_transform", "odometry_msg", "parameter_msg", "pose_of", "quaternion_from_yaw",
    "status_code_msg", "transform_from_odometry", "twist_args", "twist_msg", "yaw_of",
]

#: (x, y, yaw) in the 6x6 (x, y, z, roll, pitch, yaw) matrices of nav_msgs/Odometry
POSE_AXES = (0, 1, 5)
#: (vx, wz) in the 6x6 (vx, vy, vz, wx, wy, wz) twist matrices
TWIST_AXES = (0, 5)


def _field_names(cls: Any) -> tuple[str, ...]:
    """A message class's field names in order (ROS 1: ``__slots__``; ROS 2's slots are
    ``_name`` and more, its fields come from ``get_fields_and_field_types``)."""
    fields = getattr(cls, "get_fields_and_field_types", None)
    return tuple(fields()) if fields is not None else tuple(cls.__slots__)


#: the woosh_msgs/Parameter fields after its header, in message order
PARAMETER_FIELDS: tuple[str, ...] = _field_names(Parameter)[1:]


def quaternion_from_yaw(yaw: float) -> Quaternion:
    """A rotation of ``yaw`` [rad] about z."""
    half = 0.5 * yaw
    return Quaternion(x=0.0, y=0.0, z=math.sin(half), w=math.cos(half))


def embed_planar(cov: Sequence[float], axes: Sequence[int], unobserved: float,
                 extra: Mapping[int, float] | None = None) -> list[float]:
    """A 6x6 row-major covariance with the n x n row-major ``cov`` at ``axes``.

    The other diagonal entries get ``unobserved`` (a large variance: "not measured"), except
    those listed in ``extra`` (axis -> variance). Off-diagonal entries outside ``axes`` are 0.
    """
    n = len(axes)
    if len(cov) != n * n:
        raise ValueError(f"expected a {n}x{n} covariance, got {len(cov)} values")
    m = [0.0] * 36
    for i in range(6):
        m[i * 6 + i] = unobserved
    for a, ia in enumerate(axes):
        for b, ib in enumerate(axes):
            m[ia * 6 + ib] = float(cov[a * n + b])
    for axis, variance in (extra or {}).items():
        m[axis * 6 + axis] = variance
    return m


def odometry_msg(
    stamp: Any, frame_id: str, child_frame_id: str, pose: tuple[float, float, float],
    twist: tuple[float, float], pose_cov: Sequence[float], twist_cov: Sequence[float],
    unobserved: float = 1e6,
) -> Odometry:
    """nav_msgs/Odometry of a planar base.

    ``pose`` (x [m], y [m], yaw [rad]) in ``frame_id``; ``twist`` (v [m/s], w [rad/s]) in
    ``child_frame_id``; ``pose_cov`` 3x3 over (x, y, yaw), ``twist_cov`` 2x2 over (v, w),
    both row-major. The lateral velocity gets the variance of v (a differential drive cannot
    move sideways: it is known to be zero as well as v is known); the other unobserved axes
    (z, roll, pitch and their rates) get ``unobserved``.
    """
    msg = Odometry()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    msg.pose.pose.position.x, msg.pose.pose.position.y = float(pose[0]), float(pose[1])
    msg.pose.pose.orientation = quaternion_from_yaw(pose[2])
    msg.pose.covariance = embed_planar(pose_cov, POSE_AXES, unobserved)
    msg.twist.twist.linear.x = float(twist[0])
    msg.twist.twist.angular.z = float(twist[1])
    msg.twist.covariance = embed_planar(twist_cov, TWIST_AXES, unobserved,
                                        extra={1: float(twist_cov[0])})
    return msg


def transform_from_odometry(odom: Odometry) -> TransformStamped:
    """The TF ``header.frame_id -> child_frame_id`` carried by an Odometry message."""
    t = TransformStamped()
    t.header.stamp = odom.header.stamp
    t.header.frame_id = odom.header.frame_id
    t.child_frame_id = odom.child_frame_id
    p = odom.pose.pose.position
    t.transform.translation.x, t.transform.translation.y = p.x, p.y
    t.transform.translation.z = p.z
    t.transform.rotation = odom.pose.pose.orientation
    return t


def yaw_of(q: Any, what: str) -> float:
    """The heading of a quaternion message; WorldError unless it is a finite rotation."""
    return _yaw(q.x, q.y, q.z, q.w, what)


def _yaw(x: float, y: float, z: float, w: float, what: str) -> float:
    """:func:`yaw_of` of the quaternion (x, y, z, w), without a message."""
    values = (x, y, z, w)
    if not all(math.isfinite(v) for v in values):
        raise WorldError(f"{what}: the orientation has a non-finite component {values}")
    norm = math.sqrt(sum(v * v for v in values))
    if not 0.9 < norm < 1.1:
        raise WorldError(f"{what}: the orientation is not a unit quaternion (norm {norm:.3g})")
    x, y, z, w = (v / norm for v in values)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def pose_of(pose: Any, what: str) -> tuple[float, float, float]:
    """(x, y, yaw) of a geometry_msgs/Pose; WorldError if it is not finite."""
    x, y = pose.position.x, pose.position.y
    if not (math.isfinite(x) and math.isfinite(y)):
        raise WorldError(f"{what}: the position ({x}, {y}) is not finite")
    return float(x), float(y), yaw_of(pose.orientation, what)


def odom_pose(msg: Any) -> tuple[float, float, float]:
    """The pose of a nav_msgs/Odometry (/odom), as every face reads it (:func:`pose_of`)."""
    return pose_of(msg.pose.pose, "/odom")


#: the key of :func:`odom_pose` in a wire's conversions (lowerbase.ros1.wire)
ODOM_POSE = "odom_pose"


def odom_pose_of(pose: tuple[float, float, float]) -> tuple[float, float, float]:
    """What :func:`odom_pose` reads from :func:`odometry_msg` of ``pose``, without the
    message: the same floats (the heading through the message's quaternion, the same
    arithmetic as :func:`quaternion_from_yaw` then :func:`yaw_of`, without building it)."""
    half = 0.5 * pose[2]
    return float(pose[0]), float(pose[1]), _yaw(0.0, 0.0, math.sin(half), math.cos(half),
                                                "/odom")


def odom_header(stamp: Any, frame_id: str) -> Header:
    return Header(stamp=stamp, frame_id=frame_id)


def odom_transform(stamp: Any, frame_id: str, child_frame_id: str,
                   pose: tuple[float, float, float]) -> TransformStamped:
    """:func:`transform_from_odometry` of :func:`odometry_msg` with this ``pose``, without the
    message (the same values; every field given, so no default part is built and replaced:
    /odom's TF goes out at 50 Hz). Keywords only: ROS 2's messages take no positional fields
    and its Header has no ``seq``."""
    half = 0.5 * pose[2]
    return TransformStamped(
        header=Header(stamp=stamp, frame_id=frame_id), child_frame_id=child_frame_id,
        transform=Transform(translation=Vector3(x=float(pose[0]), y=float(pose[1]), z=0.0),
                            rotation=Quaternion(x=0.0, y=0.0, z=math.sin(half),
                                                w=math.cos(half))))


def imu_msg(
    stamp: Any, frame_id: str, gyro: Sequence[float], accel: Sequence[float],
    gyro_variance: float, accel_variance: float,
) -> Imu:
    """sensor_msgs/Imu of a 6-axis IMU: no orientation (covariance[0] = -1, REP-145).

    ``gyro`` [rad/s] and ``accel`` [m/s^2] (specific force: +g on z at rest) in ``frame_id``;
    variances per axis [(rad/s)^2], [(m/s^2)^2].
    """
    msg = Imu()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.orientation.w = 0.0  # all zero with covariance[0] = -1: "no orientation estimate"
    msg.orientation_covariance = [-1.0] + [0.0] * 8
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = map(float, gyro)
    lin = msg.linear_acceleration
    lin.x, lin.y, lin.z = map(float, accel)
    msg.angular_velocity_covariance = _diag3(gyro_variance)
    msg.linear_acceleration_covariance = _diag3(accel_variance)
    return msg


def _diag3(variance: float) -> list[float]:
    return [variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance]


def twist_msg(linear: float, angular: float) -> Twist:
    """geometry_msgs/Twist of the base: ``linear`` [m/s] on x, ``angular`` [rad/s] on z."""
    msg = Twist()
    msg.linear.x = float(linear)
    msg.angular.z = float(angular)
    return msg


def status_code_msg(code: int) -> UInt64:
    """std_msgs/UInt64 on status_code (bits: docs/status-codes.md)."""
    return UInt64(data=int(code) & 0xFFFF_FFFF_FFFF_FFFF)


def parameter_complete(parameters: Mapping[str, float]) -> bool:
    """True when every woosh_msgs/Parameter field was read from the lower computer."""
    return all(name in parameters for name in PARAMETER_FIELDS)


def parameter_msg(stamp: Any, parameters: Mapping[str, float]) -> Parameter:
    """woosh_msgs/Parameter from the lower computer's parameters (by their woosh names).

    Missing fields stay 0; pulsePerCircle is rounded to its uint32.
    """
    msg = Parameter()
    msg.header.stamp = stamp
    for name in PARAMETER_FIELDS:
        value = float(parameters.get(name, 0.0))
        setattr(msg, name, max(0, round(value)) if name == "pulsePerCircle" else value)
    return msg


def information_msg(stamp: Any, information: Mapping[str, Any]) -> Information:
    """woosh_msgs/Information from ``DriverCore.information()``."""
    msg = Information()
    msg.header.stamp = stamp
    for name in ("hardwareVersion", "softwareVersion", "IAPSoftwareVersion", "movebaseType"):
        setattr(msg, name, str(information.get(name, "")))
    msg.parameter = parameter_msg(stamp, information.get("parameter", {}))
    return msg


def battery_msg(stamp: Any, fields: Mapping[str, float | int]) -> Battery:
    """woosh_msgs/Battery from ``BmsFrameAccumulator.battery_fields()``."""
    msg = Battery(**fields)
    msg.header.stamp = stamp
    return msg


def bms_msg(stamp: Any, fields: Mapping[str, float | int]) -> BMS:
    """woosh_msgs/BMS from ``BmsFrameAccumulator.bms_fields()``."""
    msg = BMS(**fields)
    msg.header.stamp = stamp
    return msg


def twist_args(msg: Twist) -> tuple[float, float]:
    """(linear [m/s], angular [rad/s]) of a command; the other axes are ignored (planar base)."""
    return float(msg.linear.x), float(msg.angular.z)


def led_args(msg: LED) -> dict[str, int]:
    """``DriverCore.set_led`` keyword arguments of a woosh_msgs/LED (without the strip)."""
    return {"submodule": int(msg.submodule), "urgency": int(msg.urgency),
            "abnormal": int(msg.abnormal), "normal": int(msg.normal),
            "color": int(msg.color)}
