"""Write a run as MCAP: the driver's ROS1 topics, the ground truth and the CAN frames.

:class:`McapRecorder` is a :class:`~lowerbase.recording.publisher.RunPublisher` (the driver
listener, the frame tap and the channels; see there) writing one MCAP file
(:class:`~lowerbase.recording.sinks.McapSink`). docs/recording.md lists the topics.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from lowerbase.driver.settings import NodeSettings
from lowerbase.recording.publisher import (
    CAN_FRAME_ID,
    DECODED_PREFIX,
    FRAMES_TOPIC,
    TRUTH_TOPIC,
    RunPublisher,
    Truth,
    topic_name,
)
from lowerbase.recording.sinks import McapSink, Sink

__all__ = ["CAN_FRAME_ID", "DECODED_PREFIX", "FRAMES_TOPIC", "TRUTH_TOPIC", "McapRecorder",
           "Truth", "open_publisher", "topic_name"]


class McapRecorder(RunPublisher):
    """A RunPublisher writing ``path`` (which must end in .mcap), plus any ``extra`` sinks
    (e.g. a live ``FoxgloveSink``: the same messages, serialised once)."""

    def __init__(self, path: str | Path, *, settings: NodeSettings | None = None,
                 truth_frame: str = "odom", truth_child_frame: str = "base_link_truth",
                 decoded: bool = True, extra: tuple[Sink, ...] = ()) -> None:
        sink = McapSink(path)
        self.path = sink.path
        super().__init__([sink, *extra], settings=settings, truth_frame=truth_frame,
                         truth_child_frame=truth_child_frame, decoded=decoded)


def open_publisher(mcap: str | Path | None, foxglove: str | None, *,
                   announce: Callable[[str], None] | None = None) -> RunPublisher | None:
    """The publisher of a run: an :class:`McapRecorder` on ``mcap`` (None: no file) plus the
    live view on ``foxglove`` (HOST:PORT, None: none), or None when neither is asked. A bad
    address, a busy port or an unwritable file is one ConfigError line; nothing stays open."""
    from lowerbase.recording.live import start_live

    live = start_live(foxglove, announce=announce)
    try:
        if mcap is not None:
            return McapRecorder(mcap, extra=(live,) if live is not None else ())
        return RunPublisher([live]) if live is not None else None
    except BaseException:
        if live is not None:
            live.close()
        raise
