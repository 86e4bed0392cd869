"""The ROS-free parts of ``lowerbase robot --ros2`` (run in the ROS 1 venv, without rclpy):
the TF buffer the faces read (:class:`lowerbase.ros2.tf.TfBuffer`) and the command line."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import pytest

from lowerbase.cli import main
from lowerbase.navigation.tf_map import MapToOdom
from lowerbase.ros2.tf import TfBuffer, TransformException


def transform(t: float, parent: str, child: str, x: float, yaw: float) -> NS:
    stamp = NS(sec=int(t), nanosec=round((t - int(t)) * 1e9))
    return NS(header=NS(stamp=stamp, frame_id=parent), child_frame_id=child,
              transform=NS(translation=NS(x=x, y=0.0, z=0.0),
                           rotation=NS(x=0.0, y=0.0, z=math.sin(yaw / 2),
                                       w=math.cos(yaw / 2))))


class Rospy:
    """What MapToOdom asks of rospy: Time(0) and Time.from_sec."""

    class Time:
        def __init__(self, secs: float = 0.0) -> None:
            self.ns = round(secs * 1e9)

        @classmethod
        def from_sec(cls, seconds: float) -> Rospy.Time:
            return cls(seconds)


def test_lookups_interpolate_within_the_cache_and_refuse_outside() -> None:
    buf = TfBuffer(cache_time=10.0)
    buf.set_transform(transform(1.0, "map", "odom", 0.0, 0.0))
    buf.set_transform(transform(2.0, "map", "odom", 1.0, math.pi / 2))
    tf = MapToOdom(Rospy, "map", "odom")
    tf.listen(buf)
    x, y, yaw = tf.at(1.25)
    assert (x, y) == pytest.approx((0.25, 0.0)) and yaw == pytest.approx(math.pi / 8)
    assert tf.latest() == pytest.approx((1.0, 0.0, math.pi / 2))
    assert tf.newest() == pytest.approx(2.0)
    assert tf.at(2.5) is None and tf.at(0.5) is None  # not yet / no longer: tf2's answers
    with pytest.raises(TransformException):
        buf.lookup_transform("map", "base_link", Rospy.Time(0))


def test_the_cache_keeps_cache_time_and_yaw_takes_the_short_way() -> None:
    buf = TfBuffer(cache_time=1.0)
    for k in range(5):
        buf.set_transform(transform(float(k), "map", "odom", float(k), 0.0))
    tf = MapToOdom(Rospy, "map", "odom")
    tf.listen(buf)
    assert tf.at(2.5) is None and tf.at(3.5) == pytest.approx((3.5, 0.0, 0.0))
    buf.set_transform(transform(5.0, "map", "odom", 0.0, math.pi - 0.1))
    buf.set_transform(transform(6.0, "map", "odom", 0.0, -math.pi + 0.1))
    yaw = tf.at(5.5)[2]  # across +-pi, not through 0
    assert abs(abs(yaw) - math.pi) < 1e-9


@pytest.mark.parametrize("sim_time", [["--sim-time"], []])
def test_ros2_without_rclpy_is_one_line(capsys: pytest.CaptureFixture[str],
                                        sim_time: list[str]) -> None:
    assert main(["robot", "--ros2", *sim_time, "--map", "empty_room"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ROS 2 is not importable" in err[0] and "make ros2" in err[0]
