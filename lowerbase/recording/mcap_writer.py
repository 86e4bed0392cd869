"""Write a run as MCAP: the driver's ROS1 topics, the ground truth and the CAN frames.

:class:`McapRecorder` is two hooks on a run:

* a DriverCore listener (:meth:`McapRecorder.attach`): on the same core events as the
  driver_base node (``lowerbase.driver.node.DriverNode._on_event``) it writes what the node
  would publish, with the node's frames, topics, rates and covariances (``NodeSettings``):
  /odom_raw, /odom and /tf (odom -> base_link) on each wheel sample, /imu/data_raw,
  /status_code, and /battery and /driver_base/bms after the tick that follows a burst of BMS
  frames (the node's main loop); plus /ground_truth/odom next to /odom;
* a frame tap (``recorder(t, direction, frame_id, data)``, the SimLoop/runner ``tap``): every
  frame as can_msgs/Frame on /can/frames and its decoded signals as JSON on
  /can/decoded/<Message>.

Messages are ROS1-serialised (``message_encoding`` "ros1", schemas "ros1msg" with the full
definition) without a ROS install (:mod:`.ros1_types`). Log and publish times are the run's
time in nanoseconds (scenario seconds from the lower computer's first boot); header stamps are
the same time. docs/recording.md lists the topics.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from lowerbase import __version__
from lowerbase.driver.node import Throttle
from lowerbase.driver.settings import NodeSettings
from lowerbase.errors import ConfigError, LowerbaseError
from lowerbase.recording import messages as m
from lowerbase.recording.ros1_types import ros1_types

TRUTH_TOPIC = "/ground_truth/odom"
FRAMES_TOPIC = "/can/frames"
DECODED_PREFIX = "/can/decoded/"
CAN_FRAME_ID = "can0"  #: header.frame_id of /can/frames (the channel name of recordings)

Truth = Callable[[], "tuple[float, float, float, float, float] | None"]


def topic_name(name: str) -> str:
    """A node topic setting as the name it has in the root namespace (``status_code`` ->
    ``/status_code``; private ``~x`` -> ``/driver_base/x``)."""
    if name.startswith("~"):
        return "/driver_base/" + name[1:]
    return name if name.startswith("/") else "/" + name


class McapRecorder:
    """See the module docstring. ``close()`` (or ``with``) finishes the file."""

    def __init__(self, path: str | Path, *, settings: NodeSettings | None = None,
                 truth_frame: str = "odom", truth_child_frame: str = "base_link_truth",
                 decoded: bool = True) -> None:
        from mcap.writer import Writer

        from lowerbase.protocol.codec import default_codec

        self.path = Path(path)
        if self.path.suffix.lower() != ".mcap":
            raise ConfigError(f"{self.path}: an MCAP recording needs the suffix .mcap")
        self.settings = settings or NodeSettings()
        self.truth_frame, self.truth_child_frame = truth_frame, truth_child_frame
        self.decoded = decoded
        self.types = ros1_types()
        self.codec = default_codec()
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file: IO[bytes] = self.path.open("wb")
        except OSError as exc:
            raise ConfigError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._writer = Writer(self._file)
        self._writer.start(profile="ros1", library=f"lowerbase {__version__}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: Counter[str] = Counter()
        self.counts: Counter[str] = Counter()  #: messages written per topic
        self.dropped = 0  #: frames whose signals could not be decoded (raw frame still written)
        self._throttles = {k: Throttle(r) for k, r in self.settings.rates.items()}
        self._driver: Any = None
        self._now: Callable[[], float] = lambda: 0.0
        self._truth: Truth | None = None
        self._core_tick: Callable[[], None] = lambda: None
        self._battery_dirty = False
        self._closed = False

    # -- channels ----------------------------------------------------------------------------

    def _ros1_channel(self, topic: str, type_name: str) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            schema = self.types.schema(type_name)
            schema_id = self._schemas.get(schema.name)
            if schema_id is None:
                schema_id = self._writer.register_schema(schema.name, "ros1msg",
                                                         schema.text.encode())
                self._schemas[schema.name] = schema_id
            channel = self._writer.register_channel(topic, "ros1", schema_id,
                                                    {"md5sum": schema.md5sum})
            self._channels[topic] = channel
        return channel

    def _json_channel(self, name: str) -> int:
        topic = DECODED_PREFIX + name
        channel = self._channels.get(topic)
        if channel is None:
            msg = self.codec.message(name)
            props = {s.name: {"type": "number", **({"description": s.unit} if s.unit else {})}
                     for s in msg.signals}
            schema = {"type": "object", "title": name, "properties": props}
            schema_id = self._writer.register_schema(f"lowerbase.can.{name}", "jsonschema",
                                                     json.dumps(schema).encode())
            channel = self._writer.register_channel(topic, "json", schema_id)
            self._channels[topic] = channel
        return channel

    def write(self, topic: str, msg: Any, t: float) -> None:
        """Write the rosbags message ``msg`` on ``topic`` at ``t`` [s]."""
        channel = self._ros1_channel(topic, msg.__msgtype__)
        ns = m.to_ns(t)
        self._writer.add_message(channel, ns, self.types.serialize(msg), ns,
                                 self.counts[topic])
        self.counts[topic] += 1

    def header(self, topic: str, t: float, frame_id: str) -> Any:
        """A std_msgs/Header with the topic's next seq (from 1, as a rospy publisher's)."""
        self._seq[topic] += 1
        return m.header(self.types, self._seq[topic], t, frame_id)

    # -- frames ------------------------------------------------------------------------------

    def __call__(self, t: float, direction: str, frame_id: int, data: bytes) -> None:
        """Frame tap: /can/frames and /can/decoded/<Message>."""
        self.write(FRAMES_TOPIC, m.can_frame_msg(
            self.types, self.header(FRAMES_TOPIC, t, CAN_FRAME_ID), frame_id, data), t)
        if not self.decoded:
            return
        try:
            name, values = self.codec.decode(frame_id, data, strict=False)
        except LowerbaseError:
            self.dropped += 1  # not in the catalog, or not decodable: the raw frame is kept
            return
        channel = self._json_channel(name)
        topic = DECODED_PREFIX + name
        ns = m.to_ns(t)
        self._writer.add_message(channel, ns, json.dumps(values).encode(), ns,
                                 self.counts[topic])
        self.counts[topic] += 1

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
                gyro, accel = core.imu
                self.write(topic, m.imu_msg(
                    self.types, self.header(topic, now, s.imu_frame), gyro, accel,
                    s.imu_angular_velocity_variance, s.imu_linear_acceleration_variance), now)
        elif what == "status_code":
            if topics["status_code"] and self._throttles["status_code"].ready(core.clock.now()):
                self.write(topic_name(topics["status_code"]),
                           m.status_code_msg(self.types, core.status_code), now)
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
        for key, build, fields in (("battery", m.battery_msg, battery),
                                   ("bms", m.bms_msg, bms)):
            if self.settings.topics[key]:
                topic = topic_name(self.settings.topics[key])
                self.write(topic, build(self.types, self.header(topic, now, ""), fields), now)

    def _odometry(self, core: Any, now: float) -> None:
        s, types = self.settings, self.types
        unobserved = core.config.odometry_noise.unobserved_variance
        odo = core.odometry
        if odo is not None and s.topics["odom_raw"]:
            topic = topic_name(s.topics["odom_raw"])
            self.write(topic, m.odometry_msg(
                types, self.header(topic, now, s.odom_frame), s.base_frame,
                (odo.x, odo.y, odo.yaw), (odo.linear, odo.angular), odo.pose_covariance,
                odo.twist_covariance, unobserved), now)
        ekf = core.ekf
        topic = topic_name(s.topics["odom"] or "/odom")
        msg = m.odometry_msg(
            types, self.header(topic, now, s.odom_frame), s.base_frame, ekf.pose, ekf.twist,
            [float(v) for v in ekf.pose_covariance().ravel()],
            [float(v) for v in ekf.twist_covariance().ravel()], unobserved)
        if s.topics["odom"]:
            self.write(topic, msg, now)
        if s.publish_tf:
            self.write("/tf", m.tf_from_odometry(types, msg), now)
        truth = self._truth() if self._truth is not None else None
        if truth is not None:
            x, y, yaw, v, w = truth
            self.write(TRUTH_TOPIC, m.odometry_msg(
                types, self.header(TRUTH_TOPIC, now, self.truth_frame),
                self.truth_child_frame, (x, y, yaw), (v, w), [0.0] * 9, [0.0] * 4, 0.0), now)

    # -- the end -----------------------------------------------------------------------------

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._driver is not None:
            if self._on_event in self._driver.listeners:
                self._driver.listeners.remove(self._on_event)
            if self._driver.tick == self._tick:
                del self._driver.tick  # the class's method again
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
