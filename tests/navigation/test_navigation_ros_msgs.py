"""navigation.ros_msgs against closed forms and the world's own message builders (needs the
ROS message modules, no master)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.driver.conftest import require_ros


@pytest.fixture(autouse=True)
def _ros() -> None:
    require_ros(("rospy", "nav_msgs.msg", "sensor_msgs.msg", "geometry_msgs.msg"))


def test_costmap_translation_is_costmap_2d_publishers() -> None:
    from lowerbase.navigation.ros_msgs import COST_TRANSLATION, costmap_msg

    # costmap_2d_publisher.cpp: 0 -> 0, 253 -> 99, 254 -> 100, 255 -> -1, else 1 + 97 (i-1)/251
    for cost in range(256):
        want = {0: 0, 253: 99, 254: 100, 255: -1}.get(cost, 1 + (97 * (cost - 1)) // 251)
        assert COST_TRANSLATION[cost] == want
    costs = np.array([[0, 1, 252], [253, 254, 255]], np.uint8)
    msg = costmap_msg(costs, 0.05, (1.0, -2.0), None, "map")
    assert (msg.info.width, msg.info.height) == (3, 2)
    assert msg.data == [0, 1, 98, 99, 100, -1]  # row 0 (lowest y) first
    assert (msg.info.origin.position.x, msg.info.origin.position.y) == (1.0, -2.0)


def test_cloud_points_reads_what_the_world_publishes() -> None:
    from lowerbase.errors import WorldError
    from lowerbase.navigation.ros_msgs import cloud_points
    from lowerbase.world.ros_msgs import cloud_xyz32

    pts = np.random.default_rng(1).normal(size=(500, 3)).astype(np.float32)
    msg = cloud_xyz32(pts, "camera_1_depth_optical_frame", None)
    assert np.array_equal(cloud_points(msg), pts.astype(float))
    msg.data = msg.data[:-1]
    with pytest.raises(WorldError, match="bytes"):
        cloud_points(msg)
    msg.fields = msg.fields[:2]
    with pytest.raises(WorldError, match="x, y, z"):
        cloud_points(msg)


def test_scan_and_poses_are_checked() -> None:
    from geometry_msgs.msg import PoseStamped

    from lowerbase.errors import WorldError
    from lowerbase.navigation.ros_msgs import pose_stamped, scan_of, stamped_pose
    from lowerbase.world.lidar import LaserScan
    from lowerbase.world.ros_msgs import laser_scan

    class Stamp:
        def to_sec(self) -> float:
            return 0.0

    scan = LaserScan("base_link", 0.0, -math.pi, math.pi, 0.01, 0.0, 0.04, 0.1, 30.0,
                     np.linspace(1, 2, 629).astype(np.float32))
    msg = laser_scan(scan, None)
    msg.header.stamp = Stamp()
    back = scan_of(msg)
    assert np.array_equal(back.ranges, scan.ranges) and back.angle_increment == 0.01
    msg.angle_increment = math.nan
    with pytest.raises(WorldError, match="geometry"):
        scan_of(msg)
    p = pose_stamped((1.0, 2.0, 3.0), None, "map")
    assert stamped_pose(p, "goal", ("map",)) == pytest.approx((1.0, 2.0, 3.0))
    p.header.frame_id = "odom"
    with pytest.raises(WorldError, match="'map' frame"):
        stamped_pose(p, "goal", ("map",))
    with pytest.raises(WorldError, match="orientation"):
        stamped_pose(PoseStamped(), "goal", ("map",))  # w = 0: not a rotation


def test_the_worlds_scan_as_received_is_what_navigation_reads_back_from_the_message() -> None:
    """The lockstep robot hands navigation scan_as_received instead of scan_of(the message):
    the same fields, types and range bits (a scan of the warehouse, with its +inf returns)."""
    import dataclasses

    import rospy

    from lowerbase.navigation.ros_msgs import scan_of
    from lowerbase.world.lidar import LidarRig
    from lowerbase.world.maps import load_map
    from lowerbase.world.raycast import Scene
    from lowerbase.world.ros_msgs import laser_scan, scan_as_received
    from lowerbase.world.sensors import sensors_from_profile_file

    grid = load_map("warehouse")
    rig = LidarRig(sensors_from_profile_file().lidars)
    for k, pose in enumerate([(4.0, 4.0, 0.3), (9.5, 4.75, -2.0), (2.0, 6.0, 1.0)]):
        scan = rig.scan(Scene(grid), pose, 10.0 + k)
        stamp = rospy.Time.from_sec(12.345678 + k / 25.0)
        back = scan_of(laser_scan(scan, stamp))
        mine = scan_as_received(scan, stamp)
        for f in dataclasses.fields(back):
            a, b = getattr(back, f.name), getattr(mine, f.name)
            if f.name == "ranges":
                assert a.dtype == b.dtype == np.float32
                assert a.tobytes() == b.tobytes()
                assert b is not scan.ranges
            else:
                assert type(a) is type(b) and a == b, f.name
