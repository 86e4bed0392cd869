"""A minimal Foxglove WebSocket client (the public protocol, not foxglove-sdk): JSON
'advertise'/'subscribe' ops, binary message data frames (opcode 0x01, subscription id u32,
log time u64 ns, payload; little endian)."""

from __future__ import annotations

import contextlib
import json
import struct
import time
from collections.abc import Callable
from typing import Any

from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove.websocket.v1 under its new name (foxglove-sdk)
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"  # what Foxglove and Lichtblick releases offer


class FoxgloveClient:
    def __init__(self, url: str, subprotocols: tuple[str, ...] = (SUBPROTOCOL,)) -> None:
        self._stack = contextlib.ExitStack()
        self.ws = self._stack.enter_context(
            connect(url, subprotocols=list(subprotocols),  # type: ignore[arg-type]
                    open_timeout=10))
        self.channels: dict[str, dict[str, Any]] = {}  #: topic -> advertised channel
        self.server_info: dict[str, Any] = {}
        self._subs: dict[int, str] = {}
        self.messages: dict[str, list[tuple[int, bytes]]] = {}  #: topic -> [(log ns, payload)]

    def pump_until(self, done: Callable[[], bool], timeout: float = 20.0) -> None:
        """Read until ``done()`` (AssertionError after ``timeout`` s: the server never sent
        what was expected)."""
        deadline = time.monotonic() + timeout
        while not done():
            left = deadline - time.monotonic()
            assert left > 0, "the server did not send what was expected"
            try:
                raw = self.ws.recv(timeout=min(left, 0.5))
            except TimeoutError:
                continue
            self._handle(raw)

    def _handle(self, raw: str | bytes) -> None:
        if isinstance(raw, str):
            msg = json.loads(raw)
            if msg["op"] == "serverInfo":
                self.server_info = msg
            elif msg["op"] == "advertise":
                for ch in msg["channels"]:
                    self.channels[ch["topic"]] = ch
            elif msg["op"] == "unadvertise":
                ids = set(msg["channelIds"])
                self.channels = {t: c for t, c in self.channels.items() if c["id"] not in ids}
            return
        assert raw[0] == 0x01, f"unexpected binary opcode {raw[0]}"
        sub, ns = struct.unpack_from("<IQ", raw, 1)
        self.messages.setdefault(self._subs[sub], []).append((ns, bytes(raw[13:])))

    def subscribe(self, *topics: str) -> None:
        subs = []
        for topic in topics:
            sub = len(self._subs) + 1
            self._subs[sub] = topic
            subs.append({"id": sub, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def close(self) -> None:
        self._stack.close()
