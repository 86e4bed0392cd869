"""The recorder of ``lowerbase robot --mcap FILE``: ROS topics and the CAN bus into one MCAP.

``python -m lowerbase.recording.rosrecord FILE.mcap [bus flags] [--topic T ...]`` is a ROS
node (``/lowerbase_recorder``) that subscribes to the robot's topics (:data:`TOPICS`) as
``rosbag record`` does: with ``rospy.AnyMsg``, so each message is written as the bytes the
publisher sent, under the type, md5sum and full definition of its connection header (an MCAP
``ros1msg`` schema, readable by Foxglove, mcap-ros1-support and ``lowerbase mcap to-bag``). A
topic's channel opens with its first message. It also reads the robot's bus (the
udp_multicast flags of ``lowerbase record``) and writes every frame as ``lowerbase record
FILE.mcap`` does: /can/frames and /can/decoded/<Message> (:class:`~.publisher.RunPublisher`'s
frame tap). Log times are the wall clock at receipt (frames: python-can's timestamps), so
both kinds share one time line also under ``--sim-time`` (the messages' header stamps are ROS
time). Ctrl-C (what ``lowerbase robot`` sends its children) finishes the file.
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
from lowerbase.recording.sinks import ChannelSpec, McapSink

#: what the robot publishes (driver, world, navigation, tasks)
TOPICS = ("/odom", "/odom_raw", "/imu/data_raw", "/battery", "/driver_base/bms",
          "/status_code", "/driver_base/link_state", "/scan", "/amcl_pose", "/map",
          "/movebase_pose2d", "/tf", "/tf_static", "/robot_status", "/move_base/NavfnROS/plan",
          "/cmd_vel")


class TopicRecorder:
    """Writes each message of ``topics`` (rospy.AnyMsg subscribers) to ``sink``; ``lock``
    guards the sink (rospy calls back from a thread per topic)."""

    def __init__(self, rospy: Any, sink: McapSink, topics: Sequence[str],
                 lock: threading.Lock) -> None:
        self.sink, self.lock = sink, lock
        self.counts: Counter[str] = Counter()
        self.dropped = 0  #: messages without a usable connection header
        self._channels: dict[str, Any] = {}
        self.closed = False  #: set (under the lock) before the sink closes
        self._subs = [rospy.Subscriber(t, rospy.AnyMsg, self._on, callback_args=t,
                                       queue_size=1000) for t in topics]

    def _on(self, msg: Any, topic: str) -> None:
        ns = time.time_ns()
        head = getattr(msg, "_connection_header", None) or {}
        if "type" not in head or "message_definition" not in head:
            self.dropped += 1
            return
        with self.lock:
            if self.closed:
                return
            handle = self._channels.get(topic)
            if handle is None:
                handle = self.sink.channel(ChannelSpec(
                    topic, "ros1", head["type"], "ros1msg", head["message_definition"].encode(),
                    {"md5sum": head.get("md5sum", "")}))
                self._channels[topic] = handle
            self.sink.message(handle, ns, bytes(msg._buff), self.counts[topic])
            self.counts[topic] += 1

    def stop(self) -> None:
        for sub in self._subs:
            sub.unregister()


def main(argv: Sequence[str] | None = None) -> int:
    from lowerbase.errors import LowerbaseError
    from lowerbase.rosnode import ros_session
    from lowerbase.transport import add_bus_arguments, config_from_args, describe, open_bus

    p = argparse.ArgumentParser(prog="python -m lowerbase.recording.rosrecord",
                                description=__doc__.split("\n\n")[0] if __doc__ else None)
    p.add_argument("file", metavar="FILE.mcap")
    add_bus_arguments(p)
    p.add_argument("--topic", action="append", metavar="T",
                   help=f"record these topics (repeatable; default: {' '.join(TOPICS)})")
    args, ros_args = p.parse_known_args(argv)
    try:
        sink = McapSink(args.file)
        config = config_from_args(args)
        bus = open_bus(config)
    except LowerbaseError as exc:
        print(f"lowerbase recorder: error: {exc}", file=sys.stderr)
        return 1
    lock = threading.Lock()
    frames = RunPublisher([sink])
    topics: Any = None
    try:
        with ros_session("recorder", "lowerbase_recorder", ros_args) as session:
            rospy = session.rospy
            topics = TopicRecorder(rospy, sink, args.topic or TOPICS, lock)
            session.announce(f"{len(topics._subs)} topics and the bus ({describe(config)}) "
                             f"-> {args.file}")
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
        with lock:
            if topics is not None:
                topics.closed = True
            frames.close()  # finishes the MCAP file (the sink is shared)
    counts = dict(topics.counts) if topics is not None else {}
    counts["/can/frames"] = frames.counts["/can/frames"]
    print(f"lowerbase recorder: {args.file}: " + ", ".join(
        f"{t} {n}" for t, n in sorted(counts.items())), file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
