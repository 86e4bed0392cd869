"""How a lowerbase face reaches ROS 2: :class:`Ros2Wire`, the rclpy twin of
:class:`lowerbase.ros1.wire.RosWire`.

A face written against a wire (publisher, subscriber, service, TF broadcasters) runs on ROS 2
through this one unchanged. What differs from ROS 1 is kept here:

- **Names.** A ROS 1 private name ``~link_state`` is ROS 2's ``~/link_state``; relative and
  absolute names resolve as on ROS 1 (against the node's namespace).
- **QoS** (:func:`qos_for`): a latched ROS 1 topic is reliable + transient local, depth 1
  (/tf_static, /map, /driver_base/parameter, ...); sensor topics (:data:`SENSOR_TOPICS`:
  /scan, /imu/data_raw, ...) get rclpy's sensor-data profile (best effort, depth 5); anything
  else (/odom, /tf, the command topics) is reliable, volatile, with the ROS 1 queue size as
  its depth.
- **Services.** A ROS 1 handler takes the request and returns the response; rclpy's also
  gets an empty response: it is ignored, the handler's is returned.
- **TF.** /tf and /tf_static carry tf2_msgs/TFMessage; the static broadcaster keeps every
  transform it was given and republishes them all (tf2_ros' behaviour), transient local, so
  a late subscriber gets them.
- **Time.** The faces take stamps as rospy's ``Time``/``Duration`` (``from_sec``, ``to_sec``,
  subtraction, comparison): :class:`Stamp` is that on integer nanoseconds, and
  :class:`RclpyShim` stands in for the few rospy calls a face's loop makes (time now,
  shutdown). :class:`StampedIo` hands a ROS 2 ``builtin_interfaces/Time`` to the message
  builders of :mod:`lowerbase.driver.ros_io` instead.

Only the ROS 2 venv imports this module (``make ros2``, docs/ros2.md).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from functools import total_ordering
from types import ModuleType
from typing import Any

from builtin_interfaces.msg import Time as TimeMsg
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from tf2_msgs.msg import TFMessage

#: topics published with the sensor-data QoS (best effort: a late sample is worth nothing)
SENSOR_TOPICS = frozenset({"/scan", "/imu/data_raw", "/imu", "/scan_filtered", "/points"})


def ros2_name(name: str) -> str:
    """A ROS 1 name as ROS 2 writes it (``~x`` -> ``~/x``; the rest unchanged)."""
    if name.startswith("~") and not name.startswith("~/"):
        return "~/" + name[1:].lstrip("/") if len(name) > 1 else "~"
    return name


def qos_for(topic: str, depth: int = 10, latch: bool = False) -> QoSProfile:
    """The QoS a topic of the ROS 1 interface gets on ROS 2 (``topic`` resolved)."""
    if latch:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
    if topic in SENSOR_TOPICS:
        return qos_profile_sensor_data
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, depth),
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


@total_ordering
class Stamp:
    """rospy's Time/Duration as far as the faces use them, on integer nanoseconds."""

    __slots__ = ("ns",)

    def __init__(self, ns: int) -> None:
        self.ns = int(ns)

    @classmethod
    def from_sec(cls, seconds: float) -> Stamp:
        return cls(round(seconds * 1e9))

    def to_sec(self) -> float:
        return self.ns / 1e9

    def to_msg(self) -> TimeMsg:
        sec, nanosec = divmod(self.ns, 1_000_000_000)
        return TimeMsg(sec=sec, nanosec=nanosec)

    def __sub__(self, other: Stamp) -> Stamp:
        return Stamp(self.ns - other.ns)

    def __add__(self, other: Stamp) -> Stamp:
        return Stamp(self.ns + other.ns)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Stamp) and self.ns == other.ns

    def __lt__(self, other: Stamp) -> bool:
        return self.ns < other.ns

    def __hash__(self) -> int:
        return hash(self.ns)

    def __repr__(self) -> str:
        return f"Stamp({self.to_sec():.9f})"


class _TimeOf:
    """``rospy.Time``: ``from_sec`` and ``now`` (the node's clock: ROS time)."""

    def __init__(self, node: Node) -> None:
        self._node = node
        #: where ROS time comes from instead of the node's clock (a Ros2Clock's ``now``)
        self.source: Callable[[], float] | None = None

    @staticmethod
    def from_sec(seconds: float) -> Stamp:
        return Stamp.from_sec(seconds)

    def __call__(self, secs: int = 0, nsecs: int = 0) -> Stamp:
        """``rospy.Time(secs, nsecs)``; ``Time(0)`` is "the newest" to a TF lookup."""
        return Stamp(int(secs) * 1_000_000_000 + int(nsecs))

    def now(self) -> Stamp:
        if self.source is not None:
            return Stamp.from_sec(self.source())
        return Stamp(self._node.get_clock().now().nanoseconds)


class _DurationOf:
    @staticmethod
    def from_sec(seconds: float) -> Stamp:
        return Stamp.from_sec(seconds)


class RosException(Exception):
    """rospy's ROSException (a face catches it around a publish at shutdown)."""


class RclpyShim:
    """The rospy calls a face's loop makes (``Time``, ``Duration``, ``get_time``,
    ``is_shutdown``, ``on_shutdown``, ``signal_shutdown``, ``get_name``, the parameter server's
    ``get_param``/``get_param_cached``/``set_param`` on a dict of its own), for an rclpy
    node."""

    ROSException = RosException
    ROSInterruptException = RosException
    ROSTimeMovedBackwardsException = RosException

    def __init__(self, node: Node, params: dict[str, Any] | None = None) -> None:
        self.node = node
        self.Time = _TimeOf(node)
        self.Duration = _DurationOf()
        self._down = threading.Event()
        self._callbacks: list[Callable[[], None]] = []
        self.reason = ""
        #: what the faces read from ROS 1's parameter server (``/use_sim_time``, ...)
        self.params: dict[str, Any] = dict(params or {})

    def get_time(self) -> float:
        return self.Time.now().to_sec()

    def get_param(self, name: str, default: Any = None) -> Any:
        return self.params.get(name, default)

    get_param_cached = get_param

    def set_param(self, name: str, value: Any) -> None:
        self.params[name] = value

    def get_name(self) -> str:
        return str(self.node.get_fully_qualified_name())

    def is_shutdown(self) -> bool:
        import rclpy

        return self._down.is_set() or not rclpy.ok(context=self.node.context)

    def on_shutdown(self, callback: Callable[[], None]) -> None:
        self._callbacks.append(callback)
        if self._down.is_set():
            callback()

    def signal_shutdown(self, reason: str) -> None:
        if self._down.is_set():
            return
        self.reason = reason
        self._down.set()
        for callback in self._callbacks:
            callback()


class StampedIo:
    """A message-builder module (:mod:`lowerbase.driver.ros_io`) whose functions take a
    :class:`Stamp` first and get a ``builtin_interfaces/Time``; everything else passes."""

    STAMPED = frozenset({"odometry_msg", "imu_msg", "parameter_msg", "information_msg",
                         "battery_msg", "bms_msg", "odom_header", "odom_transform"})

    def __init__(self, io: ModuleType) -> None:
        self._io = io

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._io, name)
        if name not in self.STAMPED:
            return value

        def stamped(stamp: Any, *args: Any, **kwargs: Any) -> Any:
            return value(stamp.to_msg() if isinstance(stamp, Stamp) else stamp,
                         *args, **kwargs)
        return stamped


class _Subscription:
    def __init__(self, node: Node, sub: Any) -> None:
        self.node, self.sub = node, sub

    def unregister(self) -> None:
        self.node.destroy_subscription(self.sub)


class _Service:
    def __init__(self, node: Node, srv: Any) -> None:
        self.node, self.srv = node, srv

    def shutdown(self) -> None:
        self.node.destroy_service(self.srv)


class TfBroadcaster:
    """tf2_ros' (static) TransformBroadcaster: ``sendTransform(t or [t, ...])``."""

    def __init__(self, node: Node, static: bool) -> None:
        self.static = static
        qos = qos_for("/tf_static", latch=True) if static else \
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
        self.pub = node.create_publisher(TFMessage, "/tf_static" if static else "/tf", qos)
        self._static: dict[str, Any] = {}  #: child frame -> its latest static transform

    def sendTransform(self, transforms: Any) -> None:
        items = list(transforms) if isinstance(transforms, (list, tuple)) else [transforms]
        if self.static:  # every static transform so far in one message (depth 1)
            for t in items:
                self._static[t.child_frame_id] = t
            items = list(self._static.values())
        self.pub.publish(TFMessage(transforms=items))


class Ros2Wire:
    """rclpy as :class:`lowerbase.ros1.wire.RosWire` is rospy (one node per process)."""

    def __init__(self, node: Node) -> None:
        self.node = node

    @property
    def node_name(self) -> str:
        return str(self.node.get_fully_qualified_name())

    def resolve(self, name: str) -> str:
        return str(self.node.resolve_topic_name(ros2_name(name)))

    def publisher(self, name: str, cls: Any, queue_size: int = 10, latch: bool = False,
                  **_: Any) -> Any:
        return self.node.create_publisher(cls, ros2_name(name),
                                          qos_for(self.resolve(name), queue_size, latch))

    def subscriber(self, name: str, cls: Any, callback: Callable[[Any], None],
                   external: bool | None = None, queue_size: int = 10, **_: Any) -> Any:
        sub = self.node.create_subscription(cls, ros2_name(name), callback,
                                            qos_for(self.resolve(name), queue_size))
        return _Subscription(self.node, sub)

    def service(self, name: str, cls: Any, handler: Callable[[Any], Any],
                blocking: bool = False) -> Any:
        """``blocking``: the handler may wait long, so it gets a callback group of its own (the
        node's default group runs one callback at a time: the faces' would wait for it)."""
        def serve(request: Any, _response: Any) -> Any:
            return handler(request)
        group = MutuallyExclusiveCallbackGroup() if blocking else None
        return _Service(self.node, self.node.create_service(cls, ros2_name(name), serve,
                                                            callback_group=group))

    def publish_converted(self, publisher: Any, msg: Any,
                          converted: dict[str, Callable[[], Any]]) -> None:
        publisher.publish(msg)

    def publish_lazy(self, publisher: Any, header: Any, build: Callable[[], Any],
                     converted: dict[str, Callable[[], Any]]) -> None:
        publisher.publish(build())

    def convert(self, msg: Any, key: str, conversion: Callable[[Any], Any]) -> Any:
        return conversion(msg)

    def action_server(self, name: str, cls: Any, execute: Callable[[Any], None],
                      auto_start: bool = False) -> Any:
        """actionlib's SimpleActionServer calls on rclpy.action (:mod:`lowerbase.ros2.
        actions`; the ends mapped to ROS 2's states there)."""
        from lowerbase.ros2.actions import SimpleActionServer

        return SimpleActionServer(self.node, ros2_name(name), cls, execute,
                                  auto_start=auto_start)

    def tf_broadcaster(self) -> TfBroadcaster:
        return TfBroadcaster(self.node, static=False)

    def static_broadcaster(self) -> TfBroadcaster:
        return TfBroadcaster(self.node, static=True)


def uses_sim_time(node: Node) -> bool:
    """True when the node's ``use_sim_time`` parameter is (ROS 2's /clock time)."""
    return bool(node.get_parameter("use_sim_time").value)


def clock_qos() -> QoSProfile:
    """/clock as rclpy's own TimeSource takes it (best effort, depth 1)."""
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
