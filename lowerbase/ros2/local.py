"""Several faces in one ROS 2 process on one clock: :class:`Ros2LocalWire`, the rclpy twin of
:class:`lowerbase.ros1.wire.LocalWire` (``lowerbase robot --ros2 --sim-time``).

The in-process part is ROS 1's own (:class:`~lowerbase.ros1.wire.Switchboard`: what one face
publishes reaches the others at once, in the publishing thread; outside input waits in the
inbox for the lockstep loop). What goes out to ROS goes through one rclpy node
(:class:`~lowerbase.ros2.wire.Ros2Wire`: QoS per topic, tf2_msgs): a message is handed to
rclpy only when a subscription on ROS matches it (or the topic is latched). The TF buffer the
faces read is :class:`lowerbase.ros2.tf.TfBuffer`. A subscription to an outside input
(:data:`~lowerbase.ros1.wire.EXTERNAL_INPUTS`: /base_cmd_vel, /initialpose, ...) also listens
on ROS; what this process published itself comes back over DDS too and is dropped there (its
publisher's gid is one of this node's, counted as ``own_dropped``), since it was delivered
in-process already.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from lowerbase.ros1.wire import EXTERNAL_INPUTS, LocalWire, Switchboard, _LocalSubscription
from lowerbase.ros1.wire import _TeeBroadcaster as _Ros1TeeBroadcaster
from lowerbase.ros1.wire import _TeePublisher as _Ros1TeePublisher
from lowerbase.ros2.tf import TfBuffer
from lowerbase.ros2.wire import Ros2Wire, qos_for


def _gid(value: Any) -> bytes:
    """A gid as bytes (MessageInfo's dict, or a TopicEndpointInfo's list)."""
    if isinstance(value, dict):
        value = value.get("data", b"")
    return bytes(value or b"")


class Ros2Switchboard(Switchboard):
    """The switchboard with a :class:`TfBuffer` and the node's own gids (see the module
    docstring)."""

    def __init__(self, shim: Any, node: Any,
                 external: frozenset[str] = EXTERNAL_INPUTS) -> None:
        super().__init__(shim, external, tf=TfBuffer(10.0))
        self.node = node
        self._own: set[bytes] = set()

    def _is_own(self, topic: str, gid: bytes) -> bool:
        if gid in self._own:
            return True
        node = self.node
        for info in node.get_publishers_info_by_topic(topic):  # this node's writers
            if info.node_name == node.get_name() and \
                    info.node_namespace == node.get_namespace():
                self._own.add(_gid(info.endpoint_gid))
        return gid in self._own

    def post_from(self, topic: str, callback: Callable[[Any], None], msg: Any,
                  info: Any) -> None:
        gid = _gid((info or {}).get("publisher_gid"))
        if gid and self._is_own(topic, gid):
            self.stats["own_dropped"] += 1
            return
        self.post(callback, msg)


class _TeePublisher(_Ros1TeePublisher):
    def _connected(self) -> bool:
        return bool(self.real.get_subscription_count() > 0)

    def get_num_connections(self) -> int:
        return int(self.real.get_subscription_count())

    def unregister(self) -> None:
        self.real.destroy()


class _TeeBroadcaster(_Ros1TeeBroadcaster):
    def _connected(self) -> bool:
        return bool(self.real.pub.get_subscription_count() > 0)


class Ros2LocalWire(LocalWire):
    """One face of several on one rclpy node (``real``); ``node`` is the node name the face
    would have alone (private names resolve under it: ``~parameter`` of driver_base is
    ``/driver_base/parameter``)."""

    def __init__(self, shim: Any, board: Ros2Switchboard, node: str, real: Ros2Wire) -> None:
        super().__init__(shim, board, node)
        self.board: Ros2Switchboard = board
        self.real = real

    def publisher(self, name: str, cls: Any, **kwargs: Any) -> Any:
        topic = self.resolve(name)
        latch = bool(kwargs.get("latch", False))
        real = self.real.publisher(topic, cls, queue_size=int(kwargs.get("queue_size", 10)),
                                   latch=latch)
        return _TeePublisher(real, self.board, topic, latch)

    def subscriber(self, name: str, cls: Any, callback: Callable[[Any], None],
                   external: bool | None = None, **kwargs: Any) -> Any:
        topic = self.resolve(name)
        board = self.board
        board.add_local(topic, callback)
        real = None
        if topic in board.external if external is None else external:
            sub = self.real.node.create_subscription(
                cls, topic, lambda m, info: board.post_from(topic, callback, m, info),
                qos_for(topic, int(kwargs.get("queue_size", 10))))
            real = _Destroy(self.real.node, sub)
        return _LocalSubscription(board, topic, callback, real)

    def service(self, name: str, cls: Any, handler: Callable[[Any], Any],
                blocking: bool = False) -> Any:
        return self.real.service(self.resolve(name), cls, handler, blocking)

    def action_server(self, name: str, cls: Any, execute: Callable[[Any], None],
                      auto_start: bool = False) -> Any:
        return self.real.action_server(self.resolve(name), cls, execute, auto_start)

    def tf_broadcaster(self) -> Any:
        return _TeeBroadcaster(self.real.tf_broadcaster(), self.board, static=False)

    def static_broadcaster(self) -> Any:
        return _TeeBroadcaster(self.real.static_broadcaster(), self.board, static=True)


class _Destroy:
    def __init__(self, node: Any, sub: Any) -> None:
        self.node, self.sub = node, sub

    def unregister(self) -> None:
        self.node.destroy_subscription(self.sub)
