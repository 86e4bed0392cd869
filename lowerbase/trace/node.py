"""TraceNavigate and ObstacleNavigate as one ROS1 node (``lowerbase trace``), on ROS time.

A thin rospy layer over :class:`~lowerbase.trace.modules.TraceModules`: the seed's seven topics
carry ``lowerbase_msgs/Protobuf`` (``type``, ``data``); the modules subscribe
msg_trace_navigate_route, msg_obstacle_navigate_route, msg_robot_laser_data and
msg_robot_global_pos and publish the two status topics and msg_robot_speed_control. The
bridges (unless ``bridges=False``, when other nodes provide them) publish /scan as
msg_robot_laser_data, the localization's TF map -> base_link as msg_robot_global_pos (every
control period) and forward msg_robot_speed_control to driver_base's /base_cmd_vel (or
/smooth_cmd_vel). driver_base/parameter gives the chassis' limits.

The modules' clock is ``rospy.get_time()`` and the loop is paced on it, so under
``/use_sim_time`` everything (the 5 s reports, the 60 s wait) follows /clock. One lock guards
the modules against rospy's callback threads. A bad envelope is counted and logged once per
topic (:class:`TraceModules`), a bad /scan or speed command likewise; never a traceback.
"""

from __future__ import annotations

import importlib
import logging
import math
import threading
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from google.protobuf.message import Message

from lowerbase.errors import WorldError
from lowerbase.navigation.controller import Limits
from lowerbase.trace import messages as m
from lowerbase.trace.base import TraceParams
from lowerbase.trace.bridges import laser_to_pb, pose_to_pb
from lowerbase.trace.modules import (
    AVOID_ROUTE,
    AVOID_STATUS,
    LASER,
    POSE,
    ROUTE,
    SPEED,
    STATUS,
    TraceModules,
)
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, Footprint
from lowerbase.world.grid import OccupancyGrid

log = logging.getLogger(__name__)

NODE_NAME = "trace_navigate"
#: [s] how long a wait for ROS time sleeps at most before it looks at the stop flags again
POLL = 0.1


@dataclass
class TraceSetup:
    """Everything the node needs, checked without ROS (see ``lowerbase.cli.trace``)."""

    grid: OccupancyGrid
    params: TraceParams = field(default_factory=TraceParams)
    footprint: Footprint = DEFAULT_FOOTPRINT
    bridges: bool = True  #: /scan, TF and the speed command bridged by this node
    cmd_vel: str = "base_cmd_vel"  #: driver_base's topic the speed bridge publishes on
    map_frame: str = "map"
    base_frame: str = "base_link"


def import_ros() -> tuple[Any, Any]:
    """(rospy, the lowerbase_msgs/Protobuf class); RosUnavailableError in one line if either
    is missing."""
    from lowerbase.errors import RosUnavailableError
    from lowerbase.ros1.node import ROS_HINT

    try:
        import rospy
    except ImportError as exc:
        raise RosUnavailableError(f"ROS is not installed ({exc}): {ROS_HINT}") from None
    try:
        protobuf = importlib.import_module("lowerbase_msgs.msg").Protobuf
    except ImportError:
        raise RosUnavailableError("lowerbase_msgs is not generated for this Python: run "
                                  "python -m lowerbase.driver.msggen") from None
    return rospy, protobuf


class RosTime:
    """A :class:`~lowerbase.clock.Clock` on ``rospy.get_time()`` (/clock's under sim time)."""

    is_simulated = False

    def __init__(self, rospy: Any, stop: threading.Event) -> None:
        self.rospy = rospy
        self.stop = stop

    def now(self) -> float:
        return float(self.rospy.get_time())

    def sleep_until(self, deadline: float) -> None:
        cond = self.rospy.rostime.get_rostime_cond()  # notified on every /clock message
        with cond:
            while (self.now() < deadline and not self.stop.is_set()
                   and not self.rospy.is_shutdown()):
                cond.wait(POLL)


class TraceNode:
    """Publishers, subscribers, bridges and the control loop around :class:`TraceModules`."""

    def __init__(self, setup: TraceSetup) -> None:
        self.rospy, self.Protobuf = import_ros()
        self.setup = setup
        self.lock = threading.RLock()
        self.stop = threading.Event()
        self.clock = RosTime(self.rospy, self.stop)
        self.modules = TraceModules(self.clock, setup.grid, self._send, setup.params,
                                    footprint=setup.footprint)
        self.stats: Counter[str] = Counter()
        self._pubs: dict[str, Any] = {}
        self._subs: list[Any] = []
        self._tf_buffer: Any = None

    # -- set-up --------------------------------------------------------------------------------
    def advertise(self) -> None:
        rospy, Protobuf = self.rospy, self.Protobuf
        from woosh_msgs.msg import Parameter

        pub, sub = rospy.Publisher, rospy.Subscriber
        self._pubs = {t: pub(t, Protobuf, queue_size=10) for t in (STATUS, AVOID_STATUS, SPEED)}
        self._subs = [sub(t, Protobuf, self._on_input, callback_args=t, queue_size=q)
                      for t, q in ((ROUTE, 10), (AVOID_ROUTE, 10), (LASER, 2), (POSE, 5))]
        self._subs.append(sub("driver_base/parameter", Parameter, self._on_parameter,
                              queue_size=2))
        if self.setup.bridges:
            import tf2_ros
            from geometry_msgs.msg import Twist
            from sensor_msgs.msg import LaserScan

            self._tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(10.0))
            self._tf_listener = tf2_ros.TransformListener(self._tf_buffer)
            self._pubs[LASER] = pub(LASER, Protobuf, queue_size=2)
            self._pubs[POSE] = pub(POSE, Protobuf, queue_size=5)
            self._pubs["cmd_vel"] = pub(self.setup.cmd_vel, Twist, queue_size=5)
            self._subs += [sub("scan", LaserScan, self._on_scan, queue_size=2),
                           sub(SPEED, Protobuf, self._on_speed, queue_size=10)]

    def _send(self, topic: str, msg: Message) -> None:
        type_name, data = m.encode(msg)
        self._publish(topic, self.Protobuf(type=type_name, data=data))

    def _publish(self, key: str, msg: Any) -> None:
        """Publish; a topic rospy closed while shutting down is not an error."""
        try:
            self._pubs[key].publish(msg)
        except self.rospy.ROSException as exc:
            if not (self.stop.is_set() or self.rospy.is_shutdown()):
                self._count("publish_failed", exc)

    def _count(self, key: str, exc: Exception) -> None:
        self.stats[key] += 1
        if self.stats[key] == 1:
            log.warning("%s (dropped; further drops are only counted)", exc)

    # -- ROS -> the modules --------------------------------------------------------------------
    def _on_input(self, msg: Any, topic: str) -> None:
        with self.lock:
            self.modules.receive(topic, msg.type, bytes(msg.data))

    def _on_parameter(self, msg: Any) -> None:
        values = {"maxLinear": float(msg.maxLinear), "maxAngular": float(msg.maxAngular)}
        if not all(math.isfinite(v) and v > 0 for v in values.values()):
            self._count("bad_parameter", WorldError(f"driver_base/parameter {values}"))
            return
        with self.lock:
            self.modules.set_limits(Limits.from_parameters(values))

    # -- the bridges ---------------------------------------------------------------------------
    def _on_scan(self, msg: Any) -> None:
        from lowerbase.navigation.ros_msgs import scan_of

        try:
            scan = scan_of(msg)
            if scan.frame_id.lstrip("/") != self.setup.base_frame:
                raise WorldError(f"/scan must be in {self.setup.base_frame!r} (the merged "
                                 f"scan), got {scan.frame_id!r}")
        except WorldError as exc:
            self._count("bad_scan", exc)
            return
        self._send(LASER, laser_to_pb(scan))

    def _on_speed(self, msg: Any) -> None:
        from lowerbase.navigation.ros_msgs import twist

        cmd = self.modules.decode(SPEED, msg.type, bytes(msg.data))
        if cmd is None:
            return
        v, w = cmd.linear, cmd.angular
        if not (math.isfinite(v) and math.isfinite(w)):
            self._count("bad_speed", WorldError(f"{SPEED}: a non-finite twist ({v}, {w})"))
            return
        self._publish("cmd_vel", twist(v, w))
        self.stats["cmd_vel"] += 1

    def _bridge_pose(self) -> None:
        import tf2_ros

        s = self.setup
        try:
            t = self._tf_buffer.lookup_transform(s.map_frame, s.base_frame, self.rospy.Time(0))
        except (tf2_ros.LookupException, tf2_ros.ConnectivityException,
                tf2_ros.ExtrapolationException):  # no localization (yet)
            self.stats["no_pose"] += 1
            return
        tr, q = t.transform.translation, t.transform.rotation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        # stamped with the transform's own time: a scan is paired with the pose of its time
        self._send(POSE, pose_to_pb((tr.x, tr.y, yaw), t.header.stamp.to_sec()))

    # -- the loop ------------------------------------------------------------------------------
    def tick(self) -> None:
        if self.setup.bridges:
            self._bridge_pose()
        with self.lock:
            self.modules.tick()

    def spin(self) -> None:
        """Until shutdown: one tick per control period of ROS time (waits for /clock first)."""
        self.rospy.on_shutdown(self.stop.set)
        self.clock.sleep_until(1e-9)  # under sim time ROS time is 0 until /clock arrives
        period = self.setup.params.period
        due = self.clock.now()
        while not self.stop.is_set() and not self.rospy.is_shutdown():
            self.tick()
            due += period
            now = self.clock.now()
            if now - due > 1.0 or due - now > 1.0 + period:  # stalled, or time went back
                due = now
            self.clock.sleep_until(due)

    def shutdown(self) -> None:
        self.stop.set()
        busy = any(nav.status == m.RUNNING for nav in self.modules.modules)
        if busy and "cmd_vel" in self._pubs:
            from lowerbase.navigation.ros_msgs import twist

            try:  # a last zero twist; rospy may already have closed the topic
                self._pubs["cmd_vel"].publish(twist(0.0, 0.0))
            except self.rospy.ROSException as exc:
                log.warning("no zero twist at shutdown: %s", exc)
        for sub in self._subs:
            sub.unregister()

    def all_stats(self) -> dict[str, int]:
        return {**dict(sorted(self.stats.items())), **self.modules.stats()}


def run(setup: TraceSetup, ros_args: Sequence[str], where: str) -> int:
    """Start rospy on the master in ROS_MASTER_URI, build the node and spin."""
    from lowerbase.ros1.node import ros_session

    import_ros()  # one line if ROS or the message modules are missing
    with ros_session("trace", NODE_NAME, ros_args) as session:
        node = TraceNode(setup)
        try:
            node.advertise()
            session.announce(where)
            node.spin()
        finally:
            node.shutdown()
            session.stopped(node.all_stats())
    return 0
