"""Conversions between navigation's ROS-free values and ROS1 messages (imports rospy's messages).

Only :mod:`lowerbase.navigation.node` and :mod:`lowerbase.navigation.actions` import this,
after checking that ROS is there. Out: nav_msgs/OccupancyGrid of a costmap (costmap_2d's
``costmap_2d_publisher`` translation), nav_msgs/Path, PoseStamped, Twist. In: LaserScan,
PointCloud2 (x, y, z float32), Polygon, PoseStamped: a non-finite number or a malformed
message is one :class:`WorldError` line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import OccupancyGrid as GridMsg
from nav_msgs.msg import Path

from lowerbase.errors import WorldError
from lowerbase.world.lidar import LaserScan as Scan
from lowerbase.world.ros_msgs import ODOM_POSE, SCAN, header, odom_pose, pose_of, yaw_quaternion

Pose = tuple[float, float, float]

__all__ = ["ODOM_POSE", "SCAN", "GridMsg", "Path", "PoseStamped", "Twist", "cloud_points",
           "costmap_msg", "odom_pose", "path_msg", "polygon_points", "pose_of", "pose_stamped",
           "scan_of", "stamped_pose", "twist"]


def _translation() -> np.ndarray:
    """costmap_2d_publisher's cost_translation_table: 0 -> 0, 253 -> 99, 254 -> 100,
    255 -> -1, 1..252 -> 1..98."""
    table = np.empty(256, np.int8)
    table[0] = 0
    i = np.arange(1, 253)
    table[1:253] = 1 + (97 * (i - 1)) // 251
    table[253], table[254], table[255] = 99, 100, -1
    return table


COST_TRANSLATION = _translation()


def costmap_msg(costs: np.ndarray, resolution: float, origin: Sequence[float], stamp: Any,
                frame_id: str) -> GridMsg:
    """A costmap's master grid (uint8 costs, row 0 at the lowest y) as OccupancyGrid."""
    msg = GridMsg()
    msg.header = header(stamp, frame_id)
    info = msg.info
    info.map_load_time = stamp
    info.resolution = float(resolution)
    info.height, info.width = (int(v) for v in costs.shape)
    info.origin.position.x, info.origin.position.y = float(origin[0]), float(origin[1])
    info.origin.orientation.w = 1.0
    msg.data = COST_TRANSLATION[np.asarray(costs, np.uint8)].ravel().tolist()
    return msg


def pose_stamped(pose: Sequence[float], stamp: Any, frame_id: str) -> PoseStamped:
    msg = PoseStamped()
    msg.header = header(stamp, frame_id)
    msg.pose.position.x, msg.pose.position.y = float(pose[0]), float(pose[1])
    q = msg.pose.orientation
    q.x, q.y, q.z, q.w = yaw_quaternion(float(pose[2]))
    return msg


def path_msg(poses: Sequence[Sequence[float]], stamp: Any, frame_id: str) -> Path:
    msg = Path()
    msg.header = header(stamp, frame_id)
    msg.poses = [pose_stamped(p, stamp, frame_id) for p in poses]
    return msg


def twist(linear: float, angular: float) -> Twist:
    msg = Twist()
    msg.linear.x, msg.angular.z = float(linear), float(angular)
    return msg


def stamped_pose(msg: Any, what: str, frames: Sequence[str]) -> Pose:
    """(x, y, yaw) of a PoseStamped in one of ``frames`` ("" counts as the first)."""
    frame = msg.header.frame_id.lstrip("/")
    if frame not in ("", *frames):
        raise WorldError(f"{what} must be in the {frames[0]!r} frame, got {frame!r}")
    return pose_of(msg.pose, what)


def polygon_points(msg: Any) -> list[tuple[float, float]]:
    """The (x, y) of a geometry_msgs/Polygon (z ignored); WorldError on non-finite ones."""
    pts = [(float(p.x), float(p.y)) for p in msg.points]
    if not all(math.isfinite(v) for p in pts for v in p):
        raise WorldError(f"set_footprint: a point is not finite: {pts}")
    return pts


def scan_of(msg: Any) -> Scan:
    """sensor_msgs/LaserScan -> the world's LaserScan (checked: finite geometry)."""
    geometry = (msg.angle_min, msg.angle_max, msg.angle_increment, msg.range_min,
                msg.range_max)
    if not all(math.isfinite(v) for v in geometry) or msg.angle_increment == 0:
        raise WorldError(f"/scan: the angles/ranges geometry {geometry} is not usable")
    ranges = np.asarray(msg.ranges, np.float32)
    return Scan(frame_id=msg.header.frame_id, stamp=msg.header.stamp.to_sec(),
                angle_min=float(msg.angle_min), angle_max=float(msg.angle_max),
                angle_increment=float(msg.angle_increment),
                time_increment=float(msg.time_increment), scan_time=float(msg.scan_time),
                range_min=float(msg.range_min), range_max=float(msg.range_max), ranges=ranges)


def cloud_points(msg: Any) -> np.ndarray:
    """The (n, 3) x, y, z of a PointCloud2 with float32 fields x, y, z (any layout)."""
    offsets = {f.name: f for f in msg.fields}
    if not {"x", "y", "z"} <= set(offsets) or any(offsets[k].datatype != 7 for k in "xyz"):
        raise WorldError("cloud: expected float32 fields x, y, z")
    width, height = int(msg.width), int(msg.height)
    n, step, row_step = width * height, int(msg.point_step), int(msg.row_step)
    data = bytes(msg.data)
    if n == 0:
        return np.empty((0, 3))
    if step < 12 or row_step < width * step or len(data) < height * row_step:
        raise WorldError(f"cloud: {len(data)} bytes for {height} rows of {row_step} bytes, "
                         f"{width} points of {step} bytes each")
    order = ">" if msg.is_bigendian else "<"
    rows = np.frombuffer(data, np.uint8, height * row_step).reshape(height, row_step)
    rows = rows[:, :width * step].reshape(n, step)
    out = np.empty((n, 3))
    for i, k in enumerate("xyz"):
        off = int(offsets[k].offset)
        if off + 4 > step:
            raise WorldError(f"cloud: field {k} at byte {off} lies outside a {step}-byte point")
        out[:, i] = rows[:, off:off + 4].copy().view(f"{order}f4").ravel()
    return out
