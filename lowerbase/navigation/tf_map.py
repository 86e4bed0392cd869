"""TF map -> odom for the navigation node (rospy side): the newest one (the robot's pose now,
as move_base's getRobotPose), the one at a stamp and the newest stamp TF has it at (for
:class:`lowerbase.world.stamped.StampedSensors`, which pairs each scan and cloud with
map -> odom at its own stamp, never the newest)."""

from __future__ import annotations

from typing import Any

from lowerbase.navigation.loop import pose2d

Pose = tuple[float, float, float]


class MapToOdom:
    """Lookups in a ``tf2_ros.Buffer`` (None until :meth:`listen`)."""

    def __init__(self, rospy: Any, map_frame: str, odom_frame: str) -> None:
        self.rospy = rospy
        self.frames = (map_frame, odom_frame)
        self.buffer: Any = None

    def listen(self, buffer: Any = None) -> None:
        """Look up in ``buffer`` (a tf2_ros.Buffer that something else fills, e.g.
        :meth:`lowerbase.ros1.wire.RosWire.tf_buffer`, or one with a ``TransformException``
        of its own, as :class:`lowerbase.ros2.tf.TfBuffer`); None: a buffer of its own on
        /tf."""
        if buffer is None:
            import tf2_ros

            buffer = tf2_ros.Buffer(cache_time=self.rospy.Duration(10.0))
            self._listener = tf2_ros.TransformListener(buffer)
        self.buffer = buffer
        # a tf2_ros.Buffer's lookup_transform is its can_transform (whose answer it drops;
        # with no timeout it never waits) then lookup_transform_core: the core alone answers
        # the same transform or raises the same exception, without the two Durations and the
        # second search every call
        self._lookup_in = getattr(buffer, "lookup_transform_core", buffer.lookup_transform)
        self._latest_stamp = self.rospy.Time(0)
        errors = getattr(buffer, "TransformException", None)  # a buffer of its own kind
        if errors is None:
            import tf2_ros

            errors = tf2_ros.TransformException
        self._errors: type[Exception] = errors

    def _lookup(self, stamp: Any) -> Pose | None:
        if self.buffer is None:
            return None
        try:
            t = self._lookup_in(*self.frames, stamp)
        except self._errors:  # none (yet), or not at that stamp
            return None
        return pose2d(t.transform)

    def latest(self) -> Pose | None:
        """The newest map -> odom; None: no localization (yet)."""
        return self._lookup(self._latest_stamp)

    def at(self, stamp: float) -> Pose | None:
        """Map -> odom at ``stamp`` [s] (interpolated by tf2); None when TF has none there:
        not yet (after its newest) or no longer (before its cache)."""
        return self._lookup(self.rospy.Time.from_sec(stamp))

    def newest(self) -> float | None:
        """[s] the newest stamp TF has map -> odom at; None: none yet."""
        if self.buffer is None:
            return None
        try:
            t = self.buffer.get_latest_common_time(*self.frames)
        except self._errors:
            return None
        return float(t.to_sec())
