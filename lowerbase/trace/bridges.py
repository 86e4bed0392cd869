"""Bridges between the chassis' world and the seed's messages, ROS-free.

- /scan (:class:`~lowerbase.world.lidar.LaserScan`) -> GLaserScan (msg_robot_laser_data)
- the localization pose (movebase_pose2d, map frame) -> RobotPose2D (msg_robot_global_pos)
- GRobotSpeedControl (msg_robot_speed_control) -> driver_base's twist (/base_cmd_vel), so
  the emulator moves; NaN/inf is refused by driver_base and counted there.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from lowerbase.trace import messages as m
from lowerbase.world.lidar import LaserScan


def laser_to_pb(scan: LaserScan) -> m.GLaserScan:
    return m.GLaserScan(stamp=scan.stamp, frame_id=scan.frame_id, angle_min=scan.angle_min,
                        angle_max=scan.angle_max, angle_increment=scan.angle_increment,
                        time_increment=scan.time_increment, scan_time=scan.scan_time,
                        range_min=scan.range_min, range_max=scan.range_max,
                        ranges=np.asarray(scan.ranges, np.float32).tolist())


def laser_from_pb(msg: m.GLaserScan) -> LaserScan:
    """The scan back; :class:`~lowerbase.trace.messages.TraceError` if its geometry is not
    finite (ranges may hold +inf/NaN as sensor_msgs/LaserScan does)."""
    geometry = (msg.stamp, msg.angle_min, msg.angle_max, msg.angle_increment, msg.range_min,
                msg.range_max)
    if not all(math.isfinite(v) for v in geometry) or msg.angle_increment == 0:
        raise m.TraceError(f"a GLaserScan with a non-finite or zero geometry {geometry}")
    return LaserScan(msg.frame_id, msg.stamp, msg.angle_min, msg.angle_max,
                     msg.angle_increment, msg.time_increment, msg.scan_time, msg.range_min,
                     msg.range_max, np.asarray(msg.ranges, np.float32))


def pose_to_pb(pose: Sequence[float], stamp: float) -> m.RobotPose2D:
    return m.RobotPose2D(stamp=stamp, x=pose[0], y=pose[1], theta=pose[2])


class SpeedBridge:
    """GRobotSpeedControl -> ``set_twist(linear, angular)`` of a driver_base core."""

    def __init__(self, driver: object) -> None:
        self.driver = driver
        self.forwarded = self.refused = 0

    def __call__(self, msg: m.GRobotSpeedControl) -> bool:
        ok = bool(self.driver.set_twist(msg.linear, msg.angular))  # type: ignore[attr-defined]
        self.forwarded += ok
        self.refused += not ok
        return ok
