"""A run's messages: the driver's ROS1 topics, the ground truth and the CAN frames, to sinks.

:class:`RunPublisher` is two hooks on a run, writing to one or more sinks (:mod:`.sinks`: an
MCAP file, ``live.FoxgloveSink``), so a recording and the live view carry the same channels:

* a DriverCore listener (:meth:`RunPublisher.attach`): on the same core events as the
  driver_base node (``lowerbase.driver.node.DriverNode._on_event``) it writes what the node
  would publish, with the node's frames, topics, rates and covariances (``NodeSettings``):
  /odom_raw, /odom and /tf (odom -> base_link) on each wheel sample, /imu/data_raw,
  /status_code, and /battery and /driver_base/bms after the tick that follows a burst of BMS
  frames (the node's main loop); plus /ground_truth/odom next to /odom;
* a frame tap (``publisher(t, direction, frame_id, data)``, the SimLoop/runner ``tap``): every
  frame as can_msgs/Frame on /can/frames and its decoded signals as JSON on
  /can/decoded/<Message>.

:meth:`RunPublisher.truth_sample` writes the truth alone (``lowerbase emulate``: no driver);
:meth:`RunPublisher.robot_status` the task machine's robot_status (task runs).
Messages are ROS1-serialised (``message_encoding`` "ros1", schemas "ros1msg" with the full
definition) without a ROS install: the high-rate ones packed directly (:mod:`.fastser`), the
others as rosbags objects (:mod:`.ros1_types`); each is built and serialised once,
and not at all while no sink wants its channel (a live view nobody subscribes to). Times are
the run's time in nanoseconds (scenario seconds from the lower computer's first boot); header
stamps are the same time. docs/recording.md lists the topics.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

from lowerbase.driver.node import Throttle
from lowerbase.driver.settings import NodeSettings
from lowerbase.errors import LowerbaseError
from lowerbase.recording import fastser as fs
from lowerbase.recording import messages as m
from lowerbase.recording.ros1_types import ros1_types
from lowerbase.recording.sinks import ChannelSpec, Sink

TRUTH_TOPIC = "/ground_truth/odom"
ROBOT_STATUS_TOPIC = "/robot_status"  #: the tasks node's robot_status
FRAMES_TOPIC = "/can/frames"
DECODED_PREFIX = "/can/decoded/"
CAN_FRAME_ID = "can0"  #: header.frame_id of /can/frames (the channel name of recordings)

_ZERO9, _ZERO4 = (0.0,) * 9, (0.0,) * 4  #: the truth's covariances

Truth = Callable[[], "tuple[float, float, float, float, float] | None"]


def topic_name(name: str) -> str:
    """A node topic setting as the name it has in the root namespace (``status_code`` ->
    ``/status_code``; private ``~x`` -> ``/driver_base/x``)."""
    if name.startswith("~"):
        return "/driver_base/" + name[1:]
    return name if name.startswith("/") else "/" + name


class RunPublisher:
    """See the module docstring. ``close()`` (or ``with``) closes the sinks."""

    def __init__(self, sinks: Sequence[Sink], *, settings: NodeSettings | None = None,
                 truth_frame: str = "odom", truth_child_frame: str = "base_link_truth",
                 decoded: bool = True) -> None:
        from lowerbase.protocol.codec import default_codec

        self.sinks = list(sinks)
        self.settings = settings or NodeSettings()
        self.truth_frame, self.truth_child_frame = truth_frame, truth_child_frame
        self.decoded = decoded
        self.types = ros1_types()
        self.codec = default_codec()
        self._channels: dict[str, list[tuple[Sink, Any]]] = {}
        self._seq: Counter[str] = Counter()
        self.counts: Counter[str] = Counter()  #: messages written per topic
        self.dropped = 0  #: frames whose signals could not be decoded (raw frame still written)
        self._throttles = {k: Throttle(r) for k, r in self.settings.rates.items()}
        self._driver: Any = None
        self._now: Callable[[], float] = lambda: 0.0
        self._truth: Truth | None = None
        self._core_tick: Callable[[], None] = lambda: None
        self._battery_dirty = False
        self.world_topics: Any = None  #: recording.world.WorldTopics, once attached
        self._feeds: list[Any] = []
        self._closed = False

    # -- channels ----------------------------------------------------------------------------

    def ros1_spec(self, topic: str, type_name: str) -> ChannelSpec:
        schema = self.types.schema(type_name)
        return ChannelSpec(topic, "ros1", schema.name, "ros1msg", schema.text.encode(),
                           {"md5sum": schema.md5sum})

    def json_spec(self, name: str) -> ChannelSpec:
        """The channel of catalog message ``name``'s decoded signals."""
        msg = self.codec.message(name)
        props = {s.name: {"type": "number", **({"description": s.unit} if s.unit else {})}
                 for s in msg.signals}
        schema = {"type": "object", "title": name, "properties": props}
        return ChannelSpec(DECODED_PREFIX + name, "json", f"lowerbase.can.{name}",
                           "jsonschema", json.dumps(schema).encode())

    def _open(self, topic: str, spec: Callable[[], ChannelSpec]) -> list[tuple[Sink, Any]]:
        """The (sink, handle) pairs of ``topic`` that want a message now (opened once)."""
        pairs = self._channels.get(topic)
        if pairs is None:
            made = spec()
            pairs = [(sink, sink.channel(made)) for sink in self.sinks]
            self._channels[topic] = pairs
        return [(s, h) for s, h in pairs if s.wants(h)]

    def _wanted(self, topic: str, type_name: str) -> bool:
        """Whether any sink wants ``topic`` now; if not, its header seq still advances (as a
        rospy publisher's does without subscribers)."""
        if self._open(topic, lambda: self.ros1_spec(topic, type_name)):
            return True
        self._seq[topic] += 1
        return False

    def _ros1(self, topic: str, type_name: str) -> list[tuple[Sink, Any]]:
        """The pairs that want ``topic`` now; its header seq advances either way (as a rospy
        publisher's does without subscribers): ``self._seq[topic]`` is the message's."""
        pairs = self._open(topic, lambda: self.ros1_spec(topic, type_name))
        self._seq[topic] += 1
        return pairs

    def _emit(self, topic: str, pairs: list[tuple[Sink, Any]], data: bytes, ns: int) -> None:
        seq = self.counts[topic]
        for sink, handle in pairs:
            sink.message(handle, ns, data, seq)
        self.counts[topic] += 1

    def send(self, topic: str, type_name: str, build: Callable[[int], bytes], ns: int) -> bool:
        """Write on ROS1 ``topic`` the bytes ``build(seq)`` at ``ns`` [ns]: built only if a sink
        wants the topic now; ``seq`` (the header's, from 1) advances either way."""
        pairs = self._ros1(topic, type_name)
        if pairs:
            self._emit(topic, pairs, build(self._seq[topic]), ns)
        return bool(pairs)

    def wants(self, topic: str, type_name: str) -> bool:
        """Whether a sink wants ``topic`` now (opens its channel; the seq does not move)."""
        return bool(self._open(topic, lambda: self.ros1_spec(topic, type_name)))

    def add_feed(self, feed: Any) -> None:
        """A feed (``close()``) that writes on these sinks, closed before they are: e.g. a
        world's (:func:`lowerbase.recording.world.attach_world`), whose last scan comes then."""
        self._feeds.append(feed)

    def write(self, topic: str, msg: Any, t: float) -> None:
        """Write the rosbags message ``msg`` on ``topic`` at ``t`` [s]."""
        pairs = self._open(topic, lambda: self.ros1_spec(topic, msg.__msgtype__))
        if pairs:
            self._emit(topic, pairs, self.types.serialize(msg), m.to_ns(t))

    def header(self, topic: str, t: float, frame_id: str) -> Any:
        """A std_msgs/Header with the topic's next seq (from 1, as a rospy publisher's)."""
        self._seq[topic] += 1
        return m.header(self.types, self._seq[topic], t, frame_id)

    # -- frames ------------------------------------------------------------------------------

    def __call__(self, t: float, direction: str, frame_id: int, data: bytes) -> None:
        """Frame tap: /can/frames and /can/decoded/<Message>."""
        ns = m.to_ns(t)
        pairs = self._ros1(FRAMES_TOPIC, "can_msgs/Frame")
        if pairs:
            self._emit(FRAMES_TOPIC, pairs, fs.can_frame(
                self._seq[FRAMES_TOPIC], ns, CAN_FRAME_ID, frame_id, data), ns)
        if not self.decoded:
            return
        try:
            name, values = self.codec.decode(frame_id, data, strict=False)
        except LowerbaseError:
            self.dropped += 1  # not in the catalog, or not decodable: the raw frame is kept
            return
        topic = DECODED_PREFIX + name
        pairs = self._open(topic, lambda: self.json_spec(name))
        if pairs:
            self._emit(topic, pairs, json.dumps(values).encode(), ns)

    # -- the truth ---------------------------------------------------------------------------

    def truth_sample(self, t: float, truth: tuple[float, float, float, float, float]) -> None:
        """/ground_truth/odom at ``t`` [s]: ``truth`` = (x, y, yaw, v, w)."""
        pairs = self._ros1(TRUTH_TOPIC, "nav_msgs/Odometry")
        if not pairs:
            return
        x, y, yaw, v, w = truth
        ns = m.to_ns(t)
        self._emit(TRUTH_TOPIC, pairs, fs.odometry(
            self._seq[TRUTH_TOPIC], ns, self.truth_frame, self.truth_child_frame, (x, y, yaw),
            (v, w), _ZERO9, _ZERO4, 0.0), ns)

    # -- the task machine --------------------------------------------------------------------

    def robot_status(self, t: float, status: Any) -> None:
        """/robot_status woosh_msgs/RobotStatus at ``t`` [s]: ``status`` a
        ``lowerbase.tasks.model.Status`` (the tasks node publishes one on each change)."""
        if self.wants(ROBOT_STATUS_TOPIC, "woosh_msgs/RobotStatus"):
            self.write(ROBOT_STATUS_TOPIC, m.robot_status_msg(self.types, status.fields()), t)

    # -- the driver --------------------------------------------------------------------------

    def attach(self, driver: Any, now: Callable[[], float], truth: Truth | None = None) -> None:
        """Write ``driver``'s topics (a DriverCore) stamped ``now()`` [s], and the truth
        (``truth()`` -> (x, y, yaw, v, w) or None) next to each /odom."""
        self._driver, self._now, self._truth = driver, now, truth
        driver.listeners.append(self._on_event)
        # the node publishes /battery and BMS from its main loop, once per tick after a
        # burst of BMS frames: so does this (the instance's tick is wrapped until close())
        self._core_tick = driver.tick
        driver.tick = self._tick

    def _on_event(self, what: str, core: Any) -> None:
        now = self._now()
        s = self.settings
        topics = s.topics
        if what == "odometry":
            if self._throttles["odom"].ready(core.clock.now()):
                self._odometry(core, now)
        elif what == "imu":
            if core.imu is not None and topics["imu"] and self._throttles["imu"].ready(
                    core.clock.now()):
                topic = topic_name(topics["imu"])
                pairs = self._ros1(topic, "sensor_msgs/Imu")
                if not pairs:
                    return
                gyro, accel = core.imu
                ns = m.to_ns(now)
                self._emit(topic, pairs, fs.imu(
                    self._seq[topic], ns, s.imu_frame, gyro, accel,
                    s.imu_angular_velocity_variance, s.imu_linear_acceleration_variance), ns)
        elif what == "status_code":
            if topics["status_code"] and self._throttles["status_code"].ready(core.clock.now()):
                topic = topic_name(topics["status_code"])
                pairs = self._open(topic, lambda: self.ros1_spec(topic, "std_msgs/UInt64"))
                if pairs:
                    self._emit(topic, pairs, fs.uint64(core.status_code), m.to_ns(now))
        elif what == "battery":
            self._battery_dirty = True

    def _tick(self) -> None:
        """The driver's tick, then what the node publishes after it (/battery, BMS)."""
        core = self._driver
        self._core_tick()
        if not self._battery_dirty or not self._throttles["battery"].ready(core.clock.now()):
            return
        self._battery_dirty = False
        battery, bms = core.bms.battery_fields(), core.bms.bms_fields()
        if battery is None or bms is None:
            return
        now = self._now()
        for key, build, fields, type_name in (
                ("battery", m.battery_msg, battery, "woosh_msgs/Battery"),
                ("bms", m.bms_msg, bms, "woosh_msgs/BMS")):
            if self.settings.topics[key]:
                topic = topic_name(self.settings.topics[key])
                if self._wanted(topic, type_name):
                    self.write(topic, build(self.types, self.header(topic, now, ""), fields),
                               now)

    def _odometry(self, core: Any, now: float) -> None:
        s = self.settings
        unobserved = core.config.odometry_noise.unobserved_variance
        ns = m.to_ns(now)
        odo = core.odometry
        if odo is not None and s.topics["odom_raw"]:
            topic = topic_name(s.topics["odom_raw"])
            pairs = self._ros1(topic, "nav_msgs/Odometry")
            if pairs:
                self._emit(topic, pairs, fs.odometry(
                    self._seq[topic], ns, s.odom_frame, s.base_frame, (odo.x, odo.y, odo.yaw),
                    (odo.linear, odo.angular), odo.pose_covariance, odo.twist_covariance,
                    unobserved), ns)
        ekf = core.ekf
        topic = topic_name(s.topics["odom"] or "/odom")
        odom = self._ros1(topic, "nav_msgs/Odometry") if s.topics["odom"] else []
        if not s.topics["odom"]:
            self._seq[topic] += 1  # as if published (see _ros1)
        tf = self._open("/tf", lambda: self.ros1_spec("/tf", "tf2_msgs/TFMessage")) \
            if s.publish_tf else []
        if odom:
            self._emit(topic, odom, fs.odometry(
                self._seq[topic], ns, s.odom_frame, s.base_frame, ekf.pose, ekf.twist,
                ekf.pose_covariance().ravel().tolist(), ekf.twist_covariance().ravel().tolist(),
                unobserved), ns)
        if tf:  # tf2_ros' broadcaster: the odometry's transform, inner header seq 0
            self._emit("/tf", tf, fs.tf_planar(ns, s.odom_frame, s.base_frame, ekf.pose), ns)
        truth = self._truth() if self._truth is not None else None
        if truth is not None:
            self.truth_sample(now, truth)

    # -- the end -----------------------------------------------------------------------------

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for feed in self._feeds:
            feed.close()  # e.g. a world's last scan, before the sinks close
        if self._driver is not None:
            if self._on_event in self._driver.listeners:
                self._driver.listeners.remove(self._on_event)
            if self._driver.tick == self._tick:
                del self._driver.tick  # the class's method again
        errors: list[BaseException] = []
        for sink in self.sinks:
            try:
                sink.close()
            except Exception as exc:  # close the others, then raise the first
                errors.append(exc)
        if errors:
            raise errors[0]

    def __enter__(self) -> RunPublisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
