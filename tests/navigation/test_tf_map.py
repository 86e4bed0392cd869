"""MapToOdom on a tf2_ros.Buffer (no master: debug=False) answers what the buffer's own
lookup_transform answers, through lookup_transform_core alone: the newest map -> odom, one
interpolated at a stamp, none before the cache (2 s) or after the newest, none for an unknown
frame."""

from __future__ import annotations

import math

import pytest

rospy = pytest.importorskip("rospy")
tf2_ros = pytest.importorskip("tf2_ros")

from geometry_msgs.msg import TransformStamped  # noqa: E402

from lowerbase.navigation.loop import pose2d  # noqa: E402
from lowerbase.navigation.tf_map import MapToOdom  # noqa: E402


def _buffer() -> object:
    buf = tf2_ros.Buffer(cache_time=rospy.Duration(2.0), debug=False)
    for k in range(40):
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = "map", "odom"
        t.header.stamp = rospy.Time.from_sec(1.0 + 0.1 * k)
        t.transform.translation.x, t.transform.translation.y = 0.01 * k, -0.02 * k
        yaw = 0.3 + 0.05 * k
        t.transform.rotation.z, t.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        buf.set_transform(t, "test")
    return buf


def _full(buf: object, stamp: object) -> tuple[float, float, float] | None:
    try:
        return pose2d(buf.lookup_transform("map", "odom", stamp).transform)  # type: ignore[attr-defined]
    except tf2_ros.TransformException:
        return None


def test_the_core_lookup_answers_what_lookup_transform_does() -> None:
    buf = _buffer()
    tf = MapToOdom(rospy, "map", "odom")
    tf.listen(buf)
    assert tf.latest() == _full(buf, rospy.Time(0)) is not None
    for stamp in (0.5, 2.0, 3.0, 4.0, 4.55, 4.9, 5.0, 5.01, 9.0):
        assert tf.at(stamp) == _full(buf, rospy.Time.from_sec(stamp)), stamp
    assert tf.at(4.0) is not None
    assert tf.at(2.5) is None and tf.at(0.5) is None and tf.at(5.5) is None
    other = MapToOdom(rospy, "map", "elsewhere")
    other.listen(buf)
    assert other.latest() is None and other.at(4.0) is None
