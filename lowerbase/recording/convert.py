"""MCAP <-> rosbag (.bag, ROS1 format 2.0) with the mcap reader/writer and rosbags' rosbag1.

Messages are copied as they are: a ROS1-encoded MCAP message and a bag record carry the same
bytes, so nothing is deserialised. A channel's schema becomes the connection's message
definition and back; the md5sum is the channel's ``md5sum`` metadata when present, else it is
computed from the definition. JSON channels (lowerbase's /can/decoded/<Message>) become
std_msgs/String topics holding the JSON text (rostopic echo shows it); channels of other
encodings are skipped and counted. Neither converter needs a ROS install.
"""

from __future__ import annotations

import struct
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError
from lowerbase.recording.ros1_types import md5_of_definition, ros1_types, ros2_name


@dataclass
class Converted:
    messages: int = 0
    topics: Counter[str] = field(default_factory=Counter)  #: messages per topic
    skipped: Counter[str] = field(default_factory=Counter)  #: topic -> messages not converted


def _check(src: Path, dst: Path, src_suffix: str, dst_suffix: str) -> None:
    if src.suffix.lower() != src_suffix:
        raise ConfigError(f"{src}: expected a {src_suffix} file")
    if dst.suffix.lower() != dst_suffix:
        raise ConfigError(f"{dst}: the output must end in {dst_suffix}")
    if not src.is_file():
        raise ConfigError(f"no such file: {src}")
    if dst.resolve() == src.resolve():
        raise ConfigError(f"{dst}: input and output are the same file")


def mcap_to_bag(src: str | Path, dst: str | Path) -> Converted:
    """Write the ROS1 and JSON channels of MCAP ``src`` to the rosbag ``dst``."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from rosbags.rosbag1 import Writer, WriterError

    src, dst = Path(src), Path(dst)
    _check(src, dst, ".mcap", ".bag")
    dst.unlink(missing_ok=True)  # rosbags refuses to overwrite
    string = ros1_types().schema("std_msgs/String")
    done = Converted()
    connections: dict[int, Any] = {}
    try:
        with src.open("rb") as f, Writer(dst) as writer:
            for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
                conn = connections.get(channel.id)
                if conn is None:
                    conn = _connection(writer, schema, channel, string)
                    connections[channel.id] = conn
                if conn is False:
                    done.skipped[channel.topic] += 1
                    continue
                data = message.data
                if channel.message_encoding == "json":
                    text = data
                    data = len(text).to_bytes(4, "little") + text
                writer.write(conn, message.log_time, data)
                done.messages += 1
                done.topics[channel.topic] += 1
    except (McapError, WriterError, OSError, ValueError) as exc:
        dst.unlink(missing_ok=True)
        raise ConfigError(f"cannot convert {src} to {dst}: {exc}") from None
    return done


def _connection(writer: Any, schema: Any, channel: Any, string: Any) -> Any:
    if channel.message_encoding == "json":
        return writer.add_connection(channel.topic, ros2_name(string.name),
                                     msgdef=string.text, md5sum=string.md5sum)
    if channel.message_encoding != "ros1" or schema is None or schema.encoding != "ros1msg":
        return False
    text = schema.data.decode()
    md5 = channel.metadata.get("md5sum") or md5_of_definition(schema.name, text)
    return writer.add_connection(channel.topic, ros2_name(schema.name), msgdef=text,
                                 md5sum=md5)


def bag_to_mcap(src: str | Path, dst: str | Path) -> Converted:
    """Write every connection of the rosbag ``src`` to MCAP ``dst`` as ROS1 channels."""
    from mcap.writer import Writer
    from rosbags.rosbag1 import Reader, ReaderError

    from lowerbase import __version__

    src, dst = Path(src), Path(dst)
    _check(src, dst, ".bag", ".mcap")
    done = Converted()
    try:
        with Reader(src) as reader, dst.open("wb") as f:
            out = Writer(f)
            out.start(profile="ros1", library=f"lowerbase {__version__}")
            schemas: dict[tuple[str, str], int] = {}
            channels: dict[int, int] = {}
            for conn in reader.connections:
                name = conn.msgtype.replace("/msg/", "/")
                text = str(conn.msgdef.data)
                key = (name, text)
                if key not in schemas:
                    schemas[key] = out.register_schema(name, "ros1msg", text.encode())
                channels[conn.id] = out.register_channel(conn.topic, "ros1", schemas[key],
                                                         {"md5sum": conn.digest})
            seq: Counter[int] = Counter()
            for conn, stamp, data in reader.messages():
                out.add_message(channels[conn.id], stamp, bytes(data), stamp, seq[conn.id])
                seq[conn.id] += 1
                done.messages += 1
                done.topics[conn.topic] += 1
            out.finish()
    except (ReaderError, OSError, ValueError) as exc:
        dst.unlink(missing_ok=True)
        raise ConfigError(f"cannot convert {src} to {dst}: {exc}") from None
    return done


def mcap_summary(path: str | Path) -> list[str]:
    """Lines: the time span, then ``topic  type  count`` per channel."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"no such file: {p}")
    try:
        with p.open("rb") as f:
            summary = make_reader(f).get_summary()
    except (McapError, OSError, ValueError) as exc:
        raise ConfigError(f"cannot read {p}: {exc}") from None
    if summary is None or summary.statistics is None:
        raise ConfigError(f"{p}: no summary section (an unfinished recording?)")
    stats = summary.statistics
    span = (stats.message_end_time - stats.message_start_time) / 1e9
    lines = [f"{p}: {stats.message_count} message(s), {span:.3f} s, from "
             f"{stats.message_start_time / 1e9:.3f} s"]
    for cid, channel in sorted(summary.channels.items(), key=lambda kv: kv[1].topic):
        schema = summary.schemas.get(channel.schema_id)
        kind = f"{schema.name} ({channel.message_encoding})" if schema else "-"
        count = stats.channel_message_counts.get(cid, 0)
        lines.append(f"  {channel.topic:<34} {kind:<40} {count}")
    return lines


@dataclass
class Recovered:
    messages: int = 0
    topics: Counter[str] = field(default_factory=Counter)
    damage: str = ""  #: where reading stopped ("" when the file was whole)


def recover_mcap(src: str | Path, dst: str | Path) -> Recovered:
    """Every schema, channel and message that can be read from the start of ``src`` (an MCAP
    recording cut short: a recorder killed before its footer, a full disk), written to ``dst``
    as a whole MCAP file with its summary. Reading stops at the first damaged or missing
    record; what came before it is kept (a chunk still being written is lost)."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import Writer

    s, d = Path(src), Path(dst)
    _check(s, d, ".mcap", ".mcap")
    done = Recovered()
    schemas: dict[int, int] = {}
    channels: dict[int, tuple[int, str]] = {}
    try:
        with s.open("rb") as f, d.open("wb") as out:
            writer = Writer(out)
            writer.start(profile="ros1", library="lowerbase mcap recover")
            try:
                for record in StreamReader(f, record_size_limit=1 << 30).records:
                    if isinstance(record, Schema) and record.id not in schemas:
                        schemas[record.id] = writer.register_schema(
                            record.name, record.encoding, record.data)
                    elif isinstance(record, Channel) and record.id not in channels:
                        schema = schemas.get(record.schema_id, 0)
                        channels[record.id] = (writer.register_channel(
                            record.topic, record.message_encoding, schema,
                            dict(record.metadata)), record.topic)
                    elif isinstance(record, Message) and record.channel_id in channels:
                        cid, topic = channels[record.channel_id]
                        writer.add_message(cid, record.log_time, record.data,
                                           record.publish_time, record.sequence)
                        done.messages += 1
                        done.topics[topic] += 1
            except (McapError, EOFError, ValueError, struct.error) as exc:
                done.damage = str(exc) or type(exc).__name__
            writer.finish()
    except OSError as exc:
        raise ConfigError(f"cannot recover {s} into {d}: {exc.strerror or exc}") from None
    if done.damage and not (schemas or channels):
        d.unlink(missing_ok=True)
        raise ConfigError(f"{s}: no MCAP records could be read ({done.damage}): is it an "
                          "MCAP file?")
    return done
