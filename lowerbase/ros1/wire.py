"""How a lowerbase ROS face reaches ROS: :class:`RosWire` and :class:`LocalWire`.

Every rospy face (driver_base, world, navigation, tasks) makes its publishers, subscribers,
services and TF through a wire instead of calling rospy directly:

- :class:`RosWire` is rospy as it is: one face per process (``lowerbase driver``, ``lowerbase
  world``, ...), names resolved by rospy against the process' node name.
- :class:`LocalWire` puts several faces in one process on one clock (``lowerbase robot
  --sim-time``, :mod:`lowerbase.robot.lockstep`): each face keeps its own node name for
  private names (``~parameter`` of driver_base is ``/driver_base/parameter`` as before); what
  one face publishes reaches the others in this process at once, in the publishing thread,
  through a :class:`Switchboard` (never through a socket, so never late), and goes out to ROS
  for everyone else. A subscription to a topic that outside nodes are expected to publish
  (:data:`EXTERNAL_INPUTS`: a user's twist, LED, /initialpose, footprint) also listens on ROS;
  what arrives there is held in the switchboard's inbox until the lockstep loop applies it at
  the start of its next step (:meth:`Switchboard.drain`), and what this process published
  itself is dropped there (it was delivered in-process already). Such a subscription does not
  connect to this process' own publisher of the topic at all (:func:`_skip_own_publisher`):
  every message over that connection would be dropped, and each one cost the publishing
  thread rospy's hand-over to its writer and reader threads (~1 ms of wall time per
  /base_cmd_vel).

A subscriber converts what it receives through its wire (:meth:`RosWire.convert`): alone it
converts; in-process the conversion is made once per delivered message and shared by every face
that asks for it (three faces read the same /odom pose), or comes from the publisher, which
already had the value the message was built from (:meth:`RosWire.publish_converted`: the world's
scan for navigation). The message published to ROS is the same either way.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

#: topics the lockstep robot also takes from outside nodes (resolved names)
EXTERNAL_INPUTS = frozenset({
    "/base_cmd_vel", "/smooth_cmd_vel", "/rgbled", "/rgbled_shelf", "/rgbled_shelf_vendor",
    "/initialpose", "/move_base/local_costmap/set_footprint",
    "/move_base/global_costmap/set_footprint",
})


def _skip_own_publisher(rospy: Any, subscriber: Any) -> None:
    """Make ``subscriber``'s topic (rospy's ``_SubscriberImpl``, shared by every subscriber
    of the topic in this process) never connect to this process' own publisher: rospy asks
    the subscriber whether it is connected to a publisher's URI before it connects, so this
    one answers yes for this node's own URI. Outside publishers connect as before. Should a
    connection to itself be made before this (a race with rospy's registration thread),
    what comes over it is still dropped (:meth:`Switchboard.post`)."""
    impl = getattr(subscriber, "impl", None)
    if impl is None or getattr(impl, "_lowerbase_skips_own", False):
        return
    connected = impl.has_connection
    get_node_uri = rospy.core.get_node_uri

    def has_connection(endpoint_id: str) -> bool:
        return bool(endpoint_id == get_node_uri() or connected(endpoint_id))

    impl.has_connection = has_connection
    impl._lowerbase_skips_own = True


class RosWire:
    """rospy as it is (one node per process)."""

    def __init__(self, rospy: Any) -> None:
        self.rospy = rospy

    @property
    def node_name(self) -> str:
        return str(self.rospy.get_name())

    def resolve(self, name: str) -> str:
        return str(self.rospy.resolve_name(name))

    def publisher(self, name: str, cls: Any, **kwargs: Any) -> Any:
        return self.rospy.Publisher(name, cls, **kwargs)

    def subscriber(self, name: str, cls: Any, callback: Callable[[Any], None],
                   external: bool | None = None, **kwargs: Any) -> Any:
        """``external``: outside nodes publish it (LocalWire; None: :data:`EXTERNAL_INPUTS`
        says)."""
        return self.rospy.Subscriber(name, cls, callback, **kwargs)

    def service(self, name: str, cls: Any, handler: Callable[[Any], Any],
                blocking: bool = False) -> Any:
        """``blocking``: the handler may wait long (rospy serves each call in a thread of its
        own, so nothing else waits for it)."""
        return self.rospy.Service(name, cls, handler)

    def publish_converted(self, publisher: Any, msg: Any,
                          converted: dict[str, Callable[[], Any]]) -> None:
        """``publisher.publish(msg)``; in-process subscribers that :meth:`convert` ``msg`` by
        a key of ``converted`` get what its function makes (called once, only if asked for:
        it must give what their conversion of ``msg`` would). Alone nobody is in-process and
        ``converted`` is not used."""
        publisher.publish(msg)

    def publish_lazy(self, publisher: Any, header: Any, build: Callable[[], Any],
                     converted: dict[str, Callable[[], Any]]) -> None:
        """:meth:`publish_converted` of the message ``build()`` makes, built only if anyone
        reads it: alone it always is (it goes to ROS); in-process, when no outside node
        takes the topic, the faces here get a :class:`LazyMessage` with ``header`` at hand,
        and one that converts it by a key of ``converted`` never has it built."""
        self.publish_converted(publisher, build(), converted)

    def convert(self, msg: Any, key: str, conversion: Callable[[Any], Any]) -> Any:
        """``conversion(msg)``: in-process (:class:`LocalWire`) made once per delivered message
        and ``key``, or the publisher's value (:meth:`publish_converted`)."""
        return conversion(msg)

    def action_server(self, name: str, cls: Any, execute: Callable[[Any], None],
                      auto_start: bool = False) -> Any:
        """actionlib's SimpleActionServer (``name`` resolved)."""
        import actionlib  # type: ignore[import-untyped]

        return actionlib.SimpleActionServer(name, cls, execute, auto_start=auto_start)

    def tf_broadcaster(self) -> Any:
        import tf2_ros

        return tf2_ros.TransformBroadcaster()

    def static_broadcaster(self) -> Any:
        import tf2_ros

        return tf2_ros.StaticTransformBroadcaster()

    def tf_buffer(self) -> Any:
        """A tf2 buffer fed by /tf (its listener is kept with it)."""
        import tf2_ros

        buffer = tf2_ros.Buffer(cache_time=self.rospy.Duration(10.0))
        buffer._lowerbase_listener = tf2_ros.TransformListener(buffer)
        return buffer


class LazyMessage:
    """A message for the faces of this process whose body is built the first time one of
    them reads it (``build()``, once); its ``header`` is at hand (:meth:`RosWire.
    publish_lazy`). A face that reads any other field gets the built message's."""

    def __init__(self, header: Any, build: Callable[[], Any]) -> None:
        self.header = header
        self._build = build
        self._msg: Any = None

    def built(self) -> Any:
        """The message itself (built now if no one read it yet)."""
        if self._msg is None:
            self._msg = self._build()
        return self._msg

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in ("_build", "_msg"):
            raise AttributeError(name)
        return getattr(self.built(), name)


def wanted(publisher: Any) -> bool:
    """Whether building a message for ``publisher`` is worth it: a :class:`LocalWire`
    publisher answers (:meth:`_TeePublisher.wanted`); any other publisher is always wanted
    (alone, a face publishes as before)."""
    ask = getattr(publisher, "wanted", None)
    return True if ask is None else bool(ask())


def connected(publisher: Any) -> bool:
    """Whether rospy's ``publisher.publish`` would send a message anywhere: without a
    connection it serializes nothing, counts nothing and returns (a non-latched topic), so
    not calling it changes nothing. True where it cannot be told (no rospy ``impl``: an
    unregistered publisher, whose publish raises, or not rospy's)."""
    impl = getattr(publisher, "impl", None)
    return impl is None or bool(impl.has_connections())


def publish_synchronously(rospy: Any) -> int:
    """Make every publication of this process write each message on the publishing thread,
    into the subscriber's socket (rospy's publishing without a ``queue_size``), instead of a
    queue of ``queue_size`` that a writer thread empties and that drops its oldest message
    when full. In lockstep a busy host starves that thread while simulated time runs on, so
    an outside node lost messages silently (robot_state beside 12 busy processes); written
    here, a subscriber that reads slowly slows simulated time down instead (its socket's
    buffer full holds the publisher), and none is lost. Call it after every publisher is made
    (the faces', /clock, tf2's and actionlib's); returns how many publications were
    changed. A connection made before (queued already) is left as it is."""
    from rospy.impl.registration import get_topic_manager

    manager = get_topic_manager()
    if manager is None:
        return 0
    with manager.lock:
        publications = list(manager.pubs.values())
    changed = 0
    for impl in publications:
        if impl.queue_size is not None:
            impl.queue_size = None  # what rospy.Publisher(queue_size=None) leaves
            changed += 1
    return changed


class Switchboard:
    """What the faces of one process share: local subscribers by topic, the last message of
    each latched topic, the tf2 buffer the TF publishers feed, and the inbox of messages from
    outside nodes (applied by :meth:`drain`)."""

    def __init__(self, rospy: Any, external: frozenset[str] = EXTERNAL_INPUTS,
                 tf: Any = None) -> None:
        """``tf``: the buffer the TF publishers feed (None: a tf2_ros.Buffer of 10 s; ROS 2:
        :class:`lowerbase.ros2.tf.TfBuffer`)."""
        self.rospy = rospy
        self.external = external
        self.local: dict[str, list[Callable[[Any], None]]] = {}
        self.latched: dict[str, Any] = {}
        if tf is None:
            import tf2_ros

            tf = tf2_ros.Buffer(cache_time=rospy.Duration(10.0))
        self.tf = tf
        self._inbox: list[tuple[Callable[[Any], None], Any]] = []
        self._lock = threading.Lock()
        #: the messages being delivered (a callback may publish: nested), their conversions
        #: made so far and the publisher's ways to make them
        self._delivering: list[tuple[Any, dict[str, Any], dict[str, Callable[[], Any]]]] = []
        self.stats = {"local": 0, "external": 0, "own_dropped": 0}

    def deliver(self, topic: str, msg: Any, latch: bool,
                converted: dict[str, Callable[[], Any]] | None = None) -> None:
        if latch:
            self.latched[topic] = msg
        callbacks = self.local.get(topic, ())
        if not callbacks:
            return
        self._delivering.append((msg, {}, converted or {}))
        try:
            for callback in callbacks:
                self.stats["local"] += 1
                callback(msg)
        finally:
            self._delivering.pop()

    def convert(self, msg: Any, key: str, conversion: Callable[[Any], Any]) -> Any:
        """``conversion(msg)``, made once per :meth:`deliver` of ``msg`` and ``key`` (by the
        publisher's function for ``key`` if it gave one; an error is raised to each caller,
        not kept); a message not being delivered (from outside, a latched one replayed) is
        converted each time."""
        for delivering, done, makers in reversed(self._delivering):
            if delivering is msg:
                if key not in done:
                    make = makers.get(key)
                    done[key] = make() if make is not None else conversion(msg)
                return done[key]
        return conversion(msg)

    def add_local(self, topic: str, callback: Callable[[Any], None]) -> None:
        self.local.setdefault(topic, []).append(callback)
        if topic in self.latched:
            callback(self.latched[topic])

    def remove_local(self, topic: str, callback: Callable[[Any], None]) -> None:
        with_cb = self.local.get(topic, [])
        if callback in with_cb:
            with_cb.remove(callback)

    def post(self, callback: Callable[[Any], None], msg: Any) -> None:
        """A message from outside (a rospy thread): held until :meth:`drain`."""
        header = getattr(msg, "_connection_header", None) or {}
        if header.get("callerid") == self.rospy.get_name():
            self.stats["own_dropped"] += 1
            return
        with self._lock:
            self._inbox.append((callback, msg))

    def drain(self) -> int:
        """Apply what came from outside since the last call, in arrival order."""
        with self._lock:
            inbox, self._inbox = self._inbox, []
        for callback, msg in inbox:
            self.stats["external"] += 1
            callback(msg)
        return len(inbox)


class _TeePublisher:
    """A rospy publisher that also hands each message to the in-process subscribers."""

    def __init__(self, real: Any, board: Switchboard, topic: str, latch: bool) -> None:
        self.real, self.board, self.name, self.latch = real, board, topic, latch

    def publish(self, msg: Any, converted: dict[str, Callable[[], Any]] | None = None) -> None:
        self.board.deliver(self.name, msg, self.latch, converted)
        if self.latch or self._connected():  # one may have connected since publish_lazy
            self.real.publish(msg.built() if isinstance(msg, LazyMessage) else msg)

    def _connected(self) -> bool:
        return connected(self.real)

    def reaches_ros(self) -> bool:
        """Whether a message published now goes out to ROS (a connection, or latched)."""
        return bool(self.latch or self._connected())

    def wanted(self) -> bool:
        """Whether a message published now reaches anyone: a face in this process, a
        connection on ROS, or a latched topic's later subscribers."""
        return bool(self.latch or self.board.local.get(self.name) or self._connected())

    def get_num_connections(self) -> int:
        return int(self.real.get_num_connections())

    def unregister(self) -> None:
        self.real.unregister()


class _LocalSubscription:
    def __init__(self, board: Switchboard, topic: str, callback: Callable[[Any], None],
                 real: Any) -> None:
        self.board, self.name, self.callback, self.real = board, topic, callback, real

    def unregister(self) -> None:
        self.board.remove_local(self.name, self.callback)
        if self.real is not None:
            self.real.unregister()


class _TeeBroadcaster:
    """A tf2 (static) broadcaster that also fills the switchboard's buffer."""

    def __init__(self, real: Any, board: Switchboard, static: bool) -> None:
        self.real, self.board, self.static = real, board, static

    def sendTransform(self, transforms: Any) -> None:
        items = transforms if isinstance(transforms, list) else [transforms]
        for t in items:
            if self.static:
                self.board.tf.set_transform_static(t, "lowerbase")
            else:
                self.board.tf.set_transform(t, "lowerbase")
        if self.static or self._connected():
            self.real.sendTransform(transforms)

    def _connected(self) -> bool:
        """Whether anyone outside this process takes /tf."""
        return connected(getattr(self.real, "pub_tf", None))


class LocalWire(RosWire):
    """One face of several in this process (see the module docstring); ``node`` is the node
    name the face would have alone (``/driver_base``, ``/world``, ``/move_base``, ``/tasks``)."""

    def __init__(self, rospy: Any, board: Switchboard, node: str) -> None:
        super().__init__(rospy)
        self.board = board
        self.node = "/" + node.strip("/")

    @property
    def node_name(self) -> str:
        return self.node

    def resolve(self, name: str) -> str:
        if name.startswith("~"):
            rest = name[1:].lstrip("/")
            return f"{self.node}/{rest}" if rest else self.node
        return name if name.startswith("/") else "/" + name

    def publisher(self, name: str, cls: Any, **kwargs: Any) -> Any:
        topic = self.resolve(name)
        real = self.rospy.Publisher(topic, cls, **kwargs)
        return _TeePublisher(real, self.board, topic, bool(kwargs.get("latch", False)))

    def subscriber(self, name: str, cls: Any, callback: Callable[[Any], None],
                   external: bool | None = None, **kwargs: Any) -> Any:
        topic = self.resolve(name)
        self.board.add_local(topic, callback)
        real = None
        if topic in self.board.external if external is None else external:
            board = self.board
            real = self.rospy.Subscriber(topic, cls, lambda m: board.post(callback, m),
                                         **kwargs)
            _skip_own_publisher(self.rospy, real)
        return _LocalSubscription(self.board, topic, callback, real)

    def service(self, name: str, cls: Any, handler: Callable[[Any], Any],
                blocking: bool = False) -> Any:
        return self.rospy.Service(self.resolve(name), cls, handler)

    def publish_converted(self, publisher: Any, msg: Any,
                          converted: dict[str, Callable[[], Any]]) -> None:
        publisher.publish(msg, converted)

    def publish_lazy(self, publisher: Any, header: Any, build: Callable[[], Any],
                     converted: dict[str, Callable[[], Any]]) -> None:
        if getattr(publisher, "reaches_ros", lambda: True)():
            publisher.publish(build(), converted)
        else:
            publisher.publish(LazyMessage(header, build), converted)

    def convert(self, msg: Any, key: str, conversion: Callable[[Any], Any]) -> Any:
        return self.board.convert(msg, key, conversion)

    def tf_broadcaster(self) -> Any:
        return _TeeBroadcaster(super().tf_broadcaster(), self.board, static=False)

    def static_broadcaster(self) -> Any:
        return _TeeBroadcaster(super().static_broadcaster(), self.board, static=True)

    def tf_buffer(self) -> Any:
        return self.board.tf
