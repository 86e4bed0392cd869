"""Where a run's messages go: the channel description every sink shares, and the MCAP sink.

A :class:`~lowerbase.recording.publisher.RunPublisher` builds each channel once as a
:class:`ChannelSpec` (topic, encodings, schema) and each message once as bytes, and hands both
to its sinks: :class:`McapSink` writes them to a file, ``live.FoxgloveSink`` serves them to
Foxglove over WebSocket. So a recording and the live view carry the same channels and bytes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Protocol

from lowerbase import __version__
from lowerbase.errors import ConfigError


@dataclass(frozen=True)
class ChannelSpec:
    """One channel: ``message_encoding`` "ros1" (schema "ros1msg": the full concatenated
    definition) or "json" (schema "jsonschema")."""

    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    metadata: Mapping[str, str] = field(default_factory=dict)


class Sink(Protocol):
    """What a RunPublisher writes to."""

    def channel(self, spec: ChannelSpec) -> Any:
        """Open the channel; the returned handle is passed back to the other methods."""

    def wants(self, handle: Any) -> bool:
        """Whether messages on this channel go anywhere now (building them can be skipped
        when no sink wants them)."""

    def message(self, handle: Any, t_ns: int, data: bytes, sequence: int) -> None:
        """A message at log/publish time ``t_ns``; ``sequence`` counts from 0 per channel."""

    def close(self) -> None: ...


#: [bytes] of messages per MCAP chunk (compressed and written once full)
CHUNK_SIZE = 128 * 1024


class McapSink:
    """An MCAP file (profile ros1, zstd chunks: the mcap writer's defaults)."""

    def __init__(self, path: str | Path) -> None:
        from mcap.writer import Writer

        self.path = Path(path)
        if self.path.suffix.lower() != ".mcap":
            raise ConfigError(f"{self.path}: an MCAP recording needs the suffix .mcap")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file: IO[bytes] = self.path.open("wb")
        except OSError as exc:
            raise ConfigError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        # small chunks: a recorder killed before its footer loses at most the chunk being
        # written (~0.4 s of a robot's topics; 1 MiB, the default, held 3-12 s), and
        # ``lowerbase mcap recover`` rewrites the rest as a whole file
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE)
        self._writer.start(profile="ros1", library=f"lowerbase {__version__}")
        self._schemas: dict[tuple[str, str], int] = {}
        self._closed = False

    def channel(self, spec: ChannelSpec) -> int:
        key = (spec.schema_name, spec.schema_encoding)
        schema_id = self._schemas.get(key)
        if schema_id is None:
            schema_id = self._writer.register_schema(spec.schema_name, spec.schema_encoding,
                                                     spec.schema_data)
            self._schemas[key] = schema_id
        return self._writer.register_channel(spec.topic, spec.message_encoding, schema_id,
                                             dict(spec.metadata))

    def wants(self, handle: int) -> bool:
        return True

    def message(self, handle: int, t_ns: int, data: bytes, sequence: int) -> None:
        self._writer.add_message(handle, t_ns, data, t_ns, sequence)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()
