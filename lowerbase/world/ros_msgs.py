"""Conversions between the world's ROS-free values and ROS1 messages (imports rospy's messages).

Only :mod:`lowerbase.world.node` imports this, after checking that ROS is there. Messages out:
LaserScan, Image (16UC1, rgb8), CameraInfo, PointCloud2 (x, y, z float32, as
``sensor_msgs.point_cloud2.create_cloud_xyz32`` lays it out, packed with numpy),
OccupancyGrid, PoseWithCovarianceStamped, Pose2D, TransformStamped. Messages in (/odom,
/initialpose, set_map) are checked here: a non-finite number, a quaternion that is not a
rotation or a grid whose data does not fit its size is one :class:`WorldError` line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from geometry_msgs.msg import Pose2D, PoseWithCovarianceStamped, TransformStamped
from nav_msgs.msg import OccupancyGrid as GridMsg
from sensor_msgs.msg import CameraInfo, Image, LaserScan, PointCloud2, PointField
from std_msgs.msg import Header, String

from lowerbase.driver.ros_io import ODOM_POSE, odom_pose, pose_of, yaw_of
from lowerbase.errors import MapError
from lowerbase.world.camera import CameraConfig
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import LaserScan as Scan

Pose = tuple[float, float, float]

__all__ = ["ODOM_POSE", "CameraInfo", "GridMsg", "Image", "LaserScan", "PointCloud2", "Pose2D",
           "PoseWithCovarianceStamped", "String", "TransformStamped", "odom_pose", "pose_of",
           "yaw_of"]


def header(stamp: Any, frame_id: str) -> Header:
    return Header(stamp=stamp, frame_id=frame_id)


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` about z."""
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


def rpy_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of R = Rz(yaw) Ry(pitch) Rx(roll) (ROS's fixed-axis rpy)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


#: camera_link (x forward, y left, z up) -> optical frame (z forward, x right, y down)
OPTICAL = (-0.5, 0.5, -0.5, 0.5)


def transform(stamp: Any, parent: str, child: str, xyz: Sequence[float],
              quat: Sequence[float]) -> TransformStamped:
    msg = TransformStamped()
    msg.header = header(stamp, parent)
    msg.child_frame_id = child
    t, r = msg.transform.translation, msg.transform.rotation
    t.x, t.y, t.z = (float(v) for v in xyz)
    r.x, r.y, r.z, r.w = (float(v) for v in quat)
    return msg


def transform_2d(stamp: Any, parent: str, child: str, pose: Pose) -> TransformStamped:
    return transform(stamp, parent, child, (pose[0], pose[1], 0.0), yaw_quaternion(pose[2]))


def laser_scan(scan: Scan, stamp: Any) -> LaserScan:
    return LaserScan(
        header=header(stamp, scan.frame_id), angle_min=scan.angle_min,
        angle_max=scan.angle_max, angle_increment=scan.angle_increment,
        time_increment=scan.time_increment, scan_time=scan.scan_time,
        range_min=scan.range_min, range_max=scan.range_max,
        ranges=scan.ranges.astype(np.float32).tolist(), intensities=[])


def scan_as_received(scan: Scan, stamp: Any) -> Scan:
    """What a subscriber reads back from :func:`laser_scan` (``scan``, ``stamp``):
    ``lowerbase.navigation.ros_msgs.scan_of`` of that message (the stamp in seconds, the
    numbers as Python floats, the ranges through float32), made without the message
    (tests/navigation/test_navigation_ros_msgs.py)."""
    return Scan(frame_id=scan.frame_id, stamp=stamp.to_sec(), angle_min=float(scan.angle_min),
                angle_max=float(scan.angle_max), angle_increment=float(scan.angle_increment),
                time_increment=float(scan.time_increment), scan_time=float(scan.scan_time),
                range_min=float(scan.range_min), range_max=float(scan.range_max),
                ranges=scan.ranges.astype(np.float32))


#: the key of a /scan message's LaserScan in a wire's conversions (lowerbase.ros1.wire)
SCAN = "scan"


def image(array: np.ndarray, encoding: str, frame_id: str, stamp: Any) -> Image:
    """rgb8 (h, w, 3) uint8 or 16UC1 (h, w) uint16, little-endian rows."""
    if encoding == "16UC1":
        data = np.ascontiguousarray(array, dtype="<u2")
    elif encoding == "rgb8":
        data = np.ascontiguousarray(array, dtype=np.uint8)
    else:
        raise ValueError(f"unsupported encoding {encoding!r}")
    h, w = int(data.shape[0]), int(data.shape[1])
    return Image(header=header(stamp, frame_id), height=h, width=w, encoding=encoding,
                 is_bigendian=0, step=data.nbytes // h if h else 0, data=data.tobytes())


_XYZ = [PointField(name="x", offset=0, datatype=PointField.FLOAT32, count=1),
        PointField(name="y", offset=4, datatype=PointField.FLOAT32, count=1),
        PointField(name="z", offset=8, datatype=PointField.FLOAT32, count=1)]


def camera_info(config: CameraConfig, frame_id: str, stamp: Any) -> CameraInfo:
    """The pinhole the camera renders with (:class:`~lowerbase.world.camera.DepthCamera`): K from
    fx, fy, cx, cy, no distortion (plumb_bob, D = 0), R = I, P = [K | 0] (a monocular camera,
    as realsense2_camera publishes each stream's own). ROS 1's field names are D, K, R, P;
    ROS 2's d, k, r, p."""
    fx, fy, cx, cy = config.fx, config.fy, config.cx, config.cy
    matrices = {"D": [0.0] * 5, "K": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                "P": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]}
    if hasattr(CameraInfo, "d"):  # ROS 2 spells them d, k, r, p
        matrices = {k.lower(): v for k, v in matrices.items()}
    return CameraInfo(header=header(stamp, frame_id), height=config.height, width=config.width,
                      distortion_model="plumb_bob", **matrices)


def cloud_xyz32(points: np.ndarray, frame_id: str, stamp: Any) -> PointCloud2:
    """What ``point_cloud2.create_cloud_xyz32`` builds (an unordered cloud, height 1), packed
    in one numpy call instead of a struct.pack per point."""
    data = np.ascontiguousarray(points, dtype="<f4").reshape(-1, 3)
    n = int(data.shape[0])
    return PointCloud2(header=header(stamp, frame_id), height=1, width=n, fields=list(_XYZ),
                       is_bigendian=False, point_step=12, row_step=12 * n,
                       data=data.tobytes(), is_dense=False)


def grid_msg(grid: OccupancyGrid, stamp: Any, frame_id: str = "map") -> GridMsg:
    msg = GridMsg()
    msg.header = header(stamp, frame_id)
    info = msg.info
    info.map_load_time = stamp
    info.resolution = grid.resolution
    info.width, info.height = grid.width, grid.height
    ox, oy, oyaw = grid.origin
    info.origin.position.x, info.origin.position.y = ox, oy
    q = info.origin.orientation
    q.x, q.y, q.z, q.w = yaw_quaternion(oyaw)
    msg.data = grid.data.ravel().tolist()
    return msg


def grid_of(msg: GridMsg) -> OccupancyGrid:
    """The OccupancyGrid a nav_msgs/OccupancyGrid describes; WorldError/MapError if it is
    not one (data of the wrong length, values out of -1..100, a bad resolution or origin)."""
    info = msg.info
    w, h = int(info.width), int(info.height)
    if w <= 0 or h <= 0:
        raise MapError(f"map: width and height must be > 0, got {w} x {h}")
    data = msg.data
    if isinstance(data, (bytes, bytearray)):
        arr = np.frombuffer(bytes(data), dtype=np.int8)
    else:
        arr = np.asarray(data, dtype=np.int64)
    if arr.size != w * h:
        raise MapError(f"map: {arr.size} cells of data for {w} x {h} = {w * h} cells")
    if arr.size and (arr.min() < -1 or arr.max() > 100):
        raise MapError("map: cell values must be -1 (unknown) or 0..100")
    origin = pose_of(info.origin, "map origin")
    if abs(origin[2]) > 1e-9:
        raise MapError("map: the origin must not be rotated (yaw 0), as map_server's maps")
    return OccupancyGrid(arr.astype(np.int8).reshape(h, w), float(info.resolution),
                         (origin[0], origin[1], 0.0))


def pose_with_covariance(stamp: Any, frame_id: str, pose: Pose,
                         covariance: Sequence[float]) -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped()
    msg.header = header(stamp, frame_id)
    p = msg.pose.pose
    p.position.x, p.position.y = pose[0], pose[1]
    q = p.orientation
    q.x, q.y, q.z, q.w = yaw_quaternion(pose[2])
    msg.pose.covariance = [float(v) for v in covariance]
    return msg


def pose_2d(pose: Pose) -> Pose2D:
    return Pose2D(x=pose[0], y=pose[1], theta=math.atan2(math.sin(pose[2]), math.cos(pose[2])))


def covariance_of(msg: PoseWithCovarianceStamped) -> list[float] | None:
    """The 36 covariance values, or None when all are zero (rviz's "use the default")."""
    cov = [float(v) for v in msg.pose.covariance]
    return None if not any(cov) else cov
