"""The recorder of ``lowerbase robot --mcap FILE`` / ``--foxglove``: ROS topics and the CAN bus
into one MCAP and/or a live Foxglove view.

``python -m lowerbase.recording.rosrecord [FILE.mcap] [--foxglove HOST:PORT] [bus flags]
[--topic T ...]`` is a ROS node (``/lowerbase_recorder``) that subscribes to the robot's
topics (:data:`TOPICS`) as ``rosbag record`` does: with ``rospy.AnyMsg``, so each message is
written as the bytes the publisher sent, under the type, md5sum and full definition of its
connection header (an MCAP ``ros1msg`` schema, readable by Foxglove, mcap-ros1-support and
``lowerbase mcap to-bag``). A topic's channel opens with its first message. It also reads the
robot's bus (the udp_multicast flags of ``lowerbase record``) and writes every frame as
``lowerbase record FILE.mcap`` does: /can/frames and /can/decoded/<Message>
(:class:`~.publisher.RunPublisher`'s frame tap). Log times are the wall clock at receipt
(frames: python-can's timestamps), so both kinds share one time line also under
``--sim-time`` (the messages' header stamps are ROS time). The live view (``--foxglove``,
:class:`~.live.FoxgloveSink`) gets the same channels and bytes; a latched topic's last message
(per publisher: /map, /tf_static) is sent again when a client subscribes, as ROS does for a
late subscriber. Ctrl-C (what ``lowerbase robot`` sends its children) finishes the file.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections import Counter
from collections.abc import Sequence
from typing import Any

from lowerbase.recording.publisher import RunPublisher
from lowerbase.recording.sinks import ChannelSpec, McapSink, Sink

#: what the robot publishes (driver, world, navigation, tasks), and the velocity commands
#: driver_base obeys: /base_cmd_vel (navigation's, trace's) and /smooth_cmd_vel. Nothing in the
#: robot publishes or reads /cmd_vel, so it is not recorded (``--topic`` lists others instead).
TOPICS = ("/odom", "/odom_raw", "/imu/data_raw", "/battery", "/driver_base/bms",
          "/status_code", "/driver_base/link_state", "/scan", "/amcl_pose", "/map",
          "/movebase_pose2d", "/tf", "/tf_static", "/robot_status", "/move_base/NavfnROS/plan",
          "/base_cmd_vel", "/smooth_cmd_vel")


class Latched:
    """The last message of each latched topic per publisher, for the live view: sent again to
    the server when a client subscribes (the server's ``on_subscribe``)."""

    def __init__(self) -> None:
        self.handles: dict[str, Any] = {}  #: topic -> the live channel
        self.last: dict[str, dict[str, bytes]] = {}  #: topic -> callerid -> bytes
        self.closed = False

    def keep(self, topic: str, handle: Any, caller: str, data: bytes) -> None:
        self.handles[topic] = handle
        self.last.setdefault(topic, {})[caller] = data

    def on_subscribe(self, topic: str) -> None:
        handle = self.handles.get(topic)
        if handle is None or self.closed:
            return
        for data in list(self.last.get(topic, {}).values()):
            handle.log(data, time.time_ns())

    def listener(self) -> Any:
        """A foxglove ``ServerListener`` calling :meth:`on_subscribe`."""
        from foxglove.websocket import ServerListener

        latched = self

        class OnSubscribe(ServerListener):
            def on_subscribe(self, client: Any, channel: Any) -> None:
                latched.on_subscribe(channel.topic)

        return OnSubscribe()


class TopicRecorder:
    """Writes each message of ``topics`` (rospy.AnyMsg subscribers) to ``sinks``; ``lock``
    guards them (rospy calls back from a thread per topic). ``live``: the one of ``sinks``
    that is the live view, whose latched topics ``latched`` keeps."""

    def __init__(self, rospy: Any, sinks: Sequence[Sink], topics: Sequence[str],
                 lock: threading.Lock, live: Sink | None = None,
                 latched: Latched | None = None) -> None:
        self.sinks, self.lock, self.live, self.latched = sinks, lock, live, latched
        self.counts: Counter[str] = Counter()
        self.dropped = 0  #: messages without a usable connection header
        self._channels: dict[str, list[tuple[Sink, Any]]] = {}
        self.closed = False  #: set (under the lock) before the sinks close
        self._subs = [rospy.Subscriber(t, rospy.AnyMsg, self._on, callback_args=t,
                                       queue_size=1000) for t in topics]

    def _on(self, msg: Any, topic: str) -> None:
        ns = time.time_ns()
        head = getattr(msg, "_connection_header", None) or {}
        if "type" not in head or "message_definition" not in head:
            self.dropped += 1
            return
        data = bytes(msg._buff)
        with self.lock:
            if self.closed:
                return
            pairs = self._channels.get(topic)
            if pairs is None:
                spec = ChannelSpec(topic, "ros1", head["type"], "ros1msg",
                                   head["message_definition"].encode(),
                                   {"md5sum": head.get("md5sum", "")})
                pairs = [(sink, sink.channel(spec)) for sink in self.sinks]
                self._channels[topic] = pairs
            for sink, handle in pairs:
                if sink.wants(handle):
                    sink.message(handle, ns, data, self.counts[topic])
                if sink is self.live and self.latched is not None \
                        and head.get("latching") == "1":
                    self.latched.keep(topic, handle, head.get("callerid", ""), data)
            self.counts[topic] += 1

    def stop(self) -> None:
        for sub in self._subs:
            sub.unregister()


def main(argv: Sequence[str] | None = None) -> int:
    from lowerbase.errors import ConfigError, LowerbaseError
    from lowerbase.recording.live import start_live
    from lowerbase.ros1.node import ros_session
    from lowerbase.transport import add_bus_arguments, config_from_args, describe, open_bus

    p = argparse.ArgumentParser(prog="python -m lowerbase.recording.rosrecord",
                                description=__doc__.split("\n\n")[0] if __doc__ else None)
    p.add_argument("file", metavar="FILE.mcap", nargs="?", help="the MCAP file to write")
    p.add_argument("--foxglove", metavar="HOST:PORT",
                   help="serve the same channels live to Foxglove (WebSocket)")
    add_bus_arguments(p)
    p.add_argument("--topic", action="append", metavar="T",
                   help=f"record these topics (repeatable; default: {' '.join(TOPICS)})")
    args, ros_args = p.parse_known_args(argv)
    latched = Latched()
    sinks: list[Sink] = []
    bus: Any = None
    try:
        if args.file is None and args.foxglove is None:
            raise ConfigError("give FILE.mcap, --foxglove HOST:PORT or both")
        if args.file is not None:
            sinks.append(McapSink(args.file))
        live = start_live(args.foxglove, name="lowerbase robot",
                          listener=latched.listener() if args.foxglove else None,
                          announce=lambda text: print(f"lowerbase recorder: {text}",
                                                      flush=True))
        if live is not None:
            sinks.append(live)
        config = config_from_args(args)
        bus = open_bus(config)
    except LowerbaseError as exc:
        for sink in sinks:
            sink.close()
        print(f"lowerbase recorder: error: {exc}", file=sys.stderr)
        return 1
    lock = threading.Lock()
    frames = RunPublisher(sinks)
    topics: Any = None
    where = " and ".join(([args.file] if args.file else []) + ([live.url] if live else []))
    try:
        with ros_session("recorder", "lowerbase_recorder", ros_args) as session:
            rospy = session.rospy
            topics = TopicRecorder(rospy, sinks, args.topic or TOPICS, lock, live, latched)
            session.announce(f"{len(topics._subs)} topics and the bus ({describe(config)}) "
                             f"-> {where}")
            while not rospy.is_shutdown():
                msg = bus.recv(0.2)
                if msg is None or msg.is_error_frame or msg.is_remote_frame:
                    continue
                with lock:
                    frames(float(msg.timestamp), "rx", int(msg.arbitration_id), bytes(msg.data))
    except KeyboardInterrupt:
        pass
    except LowerbaseError as exc:
        print(f"lowerbase recorder: error: {exc}", file=sys.stderr)
        return 1
    finally:
        bus.shutdown()
        latched.closed = True
        with lock:
            if topics is not None:
                topics.closed = True
            frames.close()  # finishes the MCAP file and stops the server (shared sinks)
    counts = dict(topics.counts) if topics is not None else {}
    counts["/can/frames"] = frames.counts["/can/frames"]
    print(f"lowerbase recorder: {where}: " + ", ".join(
        f"{t} {n}" for t, n in sorted(counts.items())), file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
