"""The suite's client: every raw frame of the lower computer, raw sends."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from lowerbase.conformance.lower_client import LowerClient
from lowerbase.protocol.codec import Codec
from lowerbase.transport.peers import PeerMonitor

# -- the client ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class RawFrame:
    t: float  #: reception time [s] (time.monotonic), comparable with Received.t
    stamp: float  #: the bus's timestamp [s] (kernel or adapter time where it has one)
    data: bytes


class ConformanceClient(LowerClient):
    """A :class:`LowerClient` that also keeps every raw frame of the lower computer's IDs
    (also those that do not decode), sends raw payloads, and serialises sends across threads."""

    def __init__(self, bus: can.BusABC, codec: Codec | None = None,
                 on_warning: Callable[[str], None] | None = None) -> None:
        #: notices a second lower computer on the bus (its Heartbeats); warns once
        self.peers = PeerMonitor(codec)
        self.warnings: list[str] = []
        self._on_warning = on_warning
        self.raw: dict[int, list[RawFrame]] = {}
        self._raw_lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._lower_ids: frozenset[int] = frozenset()
        super().__init__(bus, codec)
        self._lower_ids = frozenset(m.frame_id for m in self.codec if "Lower" in m.senders)

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id in self._lower_ids and not (
            msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id
        ):
            frame = RawFrame(time.monotonic(), msg.timestamp or time.time(), bytes(msg.data))
            with self._raw_lock:
                self.raw.setdefault(msg.arbitration_id, []).append(frame)
            if self.peers.on_frame(msg.arbitration_id, frame.data, frame.t):
                self.warnings.append(self.peers.warning)
                if self._on_warning is not None:
                    self._on_warning(self.peers.warning)
        super().on_message_received(msg)

    def raw_frames(self, frame_id: int, since: float = 0.0, until: float = math.inf
                   ) -> list[RawFrame]:
        with self._raw_lock:
            return [f for f in self.raw.get(frame_id, ()) if since <= f.t <= until]

    def send(self, name: str, **values: Any) -> None:
        with self._send_lock:
            super().send(name, **values)

    def send_raw(self, frame_id: int, data: bytes, extended: bool = False) -> None:
        """Send any payload (wrong lengths, out-of-range values) on a standard (or extended)
        ID."""
        with self._send_lock:
            self.bus.send(can.Message(arbitration_id=frame_id, data=data,
                                      is_extended_id=extended))
