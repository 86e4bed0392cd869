"""The live view: a Foxglove WebSocket server with the channels of the MCAP recording.

``--foxglove [HOST:PORT]`` (``lowerbase emulate``, ``scenario run``, ``demo``, ``robot``) starts
:class:`FoxgloveSink`: the foxglove-sdk WebSocket server on 127.0.0.1:8765 unless the user gives
a host. The SDK speaks subprotocol ``foxglove.sdk.v1`` only (the ``foxglove.websocket.v1``
protocol under its new name); a :class:`~lowerbase.recording.wsgate.SubprotocolGate` in front
of it also lets in clients that offer only the old name (Foxglove and Lichtblick releases).
A :class:`~lowerbase.recording.publisher.RunPublisher` writes to it what it writes to an MCAP
file: the same channels, schemas and bytes. Messages of a channel no client subscribes to are
neither built nor serialised.

:class:`EmulatorFeed` is what ``lowerbase emulate`` streams (it runs no driver): the ground
truth at 50 Hz and every frame sent or received, raw and decoded.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

from lowerbase.errors import ConfigError
from lowerbase.recording.publisher import RunPublisher
from lowerbase.recording.sinks import ChannelSpec
from lowerbase.recording.wsgate import SubprotocolGate

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
DEFAULT_ADDRESS = f"{DEFAULT_HOST}:{DEFAULT_PORT}"
#: per-client queue of the server: the oldest messages are dropped when a client lags
BACKLOG = 4096


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST``, ``PORT``, ``:PORT`` or ``[v6]:PORT`` -> (host, port); host
    127.0.0.1 and port 8765 unless given. ConfigError (one line) if malformed."""
    text = text.strip()
    if text.isdigit():
        host, port_text = "", text
    elif text.startswith("["):
        inner, sep, rest = text[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            raise ConfigError(f"--foxglove {text!r}: write an IPv6 host as [ADDR]:PORT")
        host, port_text = inner, rest[1:]
    elif text.count(":") > 1:
        raise ConfigError(f"--foxglove {text!r}: write an IPv6 host as [ADDR]:PORT")
    else:
        host, _, port_text = text.partition(":")
    if not port_text:
        port_text = str(DEFAULT_PORT)
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise ConfigError(f"--foxglove {text!r}: the port must be a number 0-65535 "
                          f"(e.g. --foxglove {DEFAULT_ADDRESS})")
    if any(c.isspace() for c in host):
        raise ConfigError(f"--foxglove {text!r}: bad host (e.g. --foxglove {DEFAULT_ADDRESS})")
    return host or DEFAULT_HOST, int(port_text)


class FoxgloveSink:
    """A foxglove-sdk WebSocket server on its own Context (so several can run in a process),
    on a loopback port of its own behind a :class:`SubprotocolGate` on ``host:port``.

    ``listener``: a ``foxglove.websocket.ServerListener`` (e.g. told of each subscription).
    ConfigError (one line) when it cannot listen: the port in use, an unknown host."""

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 name: str = "lowerbase", listener: Any = None) -> None:
        import foxglove

        quiet = logging.getLogger("foxglove")  # the server's start/stop INFO lines
        if quiet.level == logging.NOTSET:
            quiet.setLevel(logging.WARNING)
        self._foxglove = foxglove
        self.context = foxglove.Context()
        def refuse(reason: str) -> ConfigError:
            return ConfigError(f"--foxglove {host}:{port}: cannot listen ({reason}); give "
                               f"another port, e.g. --foxglove {host}:{port + 1 if port else 0}")

        try:
            self.server = foxglove.start_server(name=name, host=DEFAULT_HOST, port=0,
                                                context=self.context,
                                                server_listener=listener,
                                                message_backlog_size=BACKLOG)
        except RuntimeError as exc:  # the SDK's FoxgloveError
            raise refuse(str(exc).removeprefix("FoxgloveError: ")) from None
        try:
            self.gate = SubprotocolGate(host, port, self.server.port)
        except OSError as exc:  # the port in use, an unknown host
            self.server.stop()
            raise refuse(exc.strerror or str(exc)) from None
        self.host, self.port = host, self.gate.port
        self._channels: dict[str, Any] = {}
        self._closed = False

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    def channel(self, spec: ChannelSpec) -> Any:
        schema = self._foxglove.Schema(name=spec.schema_name, encoding=spec.schema_encoding,
                                       data=spec.schema_data)
        ch = self._foxglove.Channel(spec.topic, schema=schema,
                                    message_encoding=spec.message_encoding,
                                    context=self.context, metadata=dict(spec.metadata))
        self._channels[spec.topic] = ch
        return ch.base

    @property
    def topics(self) -> list[str]:
        """The channels opened so far (advertised to every client)."""
        return list(self._channels)

    def subscribed(self, topic: str) -> bool:
        """Whether a client subscribes to ``topic`` now."""
        ch = self._channels.get(topic)
        return ch is not None and bool(ch.has_sinks())

    def wants(self, handle: Any) -> bool:
        return bool(handle.has_sinks())

    def message(self, handle: Any, t_ns: int, data: bytes, sequence: int) -> None:
        handle.log(data, t_ns)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for ch in self._channels.values():
            ch.close()
        self.gate.close()
        self.server.stop()


def start_live(address: str | None, *, name: str = "lowerbase",
               announce: Callable[[str], None] | None = None,
               listener: Any = None) -> FoxgloveSink | None:
    """``--foxglove`` value -> a started :class:`FoxgloveSink` (None: no live view), and one
    line for the user saying where to connect."""
    if address is None:
        return None
    host, port = parse_address(address)
    sink = FoxgloveSink(host, port, name=name, listener=listener)
    if announce is not None:
        announce(f"live view: Foxglove -> Open connection -> Foxglove WebSocket {sink.url} "
                 f"(layout: lowerbase/recording/foxglove-layout.json)")
    return sink


class EmulatorFeed:
    """``lowerbase emulate --foxglove``: a RunPublisher without a driver. ``on_step(mcu)``
    (the runner hook) writes the truth every ``period`` [s]; ``frame(direction, id, data)``
    every frame. Times are seconds since the lower computer's first boot."""

    def __init__(self, sinks: Sequence[Any], clock: Any, period: float = 0.02) -> None:
        self.publisher = RunPublisher(sinks)
        self.clock, self.period = clock, period
        self._t0: float | None = None
        self._next = -float("inf")

    def bind(self, mcu: Any) -> None:
        self._t0 = mcu.boot_time

    def _t(self) -> float:
        return self.clock.now() - (self._t0 if self._t0 is not None else 0.0)

    def frame(self, direction: str, frame_id: int, data: bytes) -> None:
        self.publisher(self._t(), direction, frame_id, data)

    def __call__(self, mcu: Any) -> None:
        if self._t0 is None:
            self._t0 = mcu.boot_time
        now = mcu.clock.now()
        if now < self._next:
            return
        self._next = now + self.period - 1e-9
        tr = mcu.truth
        self.publisher.truth_sample(now - self._t0, (tr.x, tr.y, tr.yaw, tr.v, tr.w))

    def close(self) -> None:
        self.publisher.close()
