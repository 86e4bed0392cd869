"""The upper computer's side of the wire, for benches and tests (cantools' Tester, our codec).

``LowerClient`` listens on a python-can bus in a background notifier, keeps every frame from the
lower computer decoded, and offers ``send`` with rolling counters and ``expect`` with a
predicate and a timeout. Frames it cannot decode are counted, not raised.
"""

from __future__ import annotations

import threading
import time
from collections import Counter, defaultdict, deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from lowerbase.errors import ProtocolError
from lowerbase.protocol.codec import Codec, default_codec
from lowerbase.transport import is_catalog_frame


@dataclass(frozen=True)
class Received:
    t: float  #: reception time [s] (time.monotonic)
    name: str
    values: dict[str, Any]
    data: bytes


class LowerClient(can.Listener):
    """Send commands to and collect frames from a lower computer."""

    def __init__(self, bus: can.BusABC, codec: Codec | None = None, history: int = 20000) -> None:
        self.bus = bus
        self.codec = codec or default_codec()
        self.stats: Counter[str] = Counter()
        self._frames: dict[str, deque[Received]] = defaultdict(lambda: deque(maxlen=history))
        self._cond = threading.Condition()
        self._counters: Counter[str] = Counter()
        self._notifier = can.Notifier(bus, [self], timeout=0.05)

    def on_message_received(self, msg: can.Message) -> None:
        now = time.monotonic()
        frame_id = msg.arbitration_id
        if not is_catalog_frame(msg):
            self.stats["not_classic"] += 1
            return
        if frame_id not in self.codec:
            self.stats["unknown_id"] += 1
            return
        m = self.codec.message(frame_id)
        if "Lower" not in m.senders:
            return  # our own frames (a multicast bus hears itself)
        try:
            values = m.decode(bytes(msg.data))
        except ProtocolError:
            self.stats["malformed"] += 1
            self.stats[f"malformed_{m.name}"] += 1
            return
        self.stats["frames"] += 1
        with self._cond:
            self._frames[m.name].append(Received(now, m.name, values, bytes(msg.data)))
            self._cond.notify_all()

    def send(self, name: str, **values: Any) -> None:
        msg = self.codec.message(name)
        if msg.has_counter and "Counter" not in values:
            values["Counter"] = self._counters[name] & 0xF
            self._counters[name] += 1
        self.bus.send(can.Message(arbitration_id=msg.frame_id, data=msg.encode(values),
                                  is_extended_id=False))

    def frames(self, name: str, since: float = 0.0) -> list[Received]:
        with self._cond:
            return [f for f in self._frames[name] if f.t >= since]

    def latest(self, name: str) -> Received | None:
        with self._cond:
            q = self._frames.get(name)
            return q[-1] if q else None

    def expect(
        self, name: str, predicate: Callable[[dict[str, Any]], bool] | None = None,
        timeout: float = 2.0, since: float | None = None,
    ) -> Received | None:
        """The first frame ``name`` received after ``since`` (default: now) that satisfies
        ``predicate``, waiting up to ``timeout`` [s]; None when none came."""
        start = time.monotonic() if since is None else since
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for f in self._frames[name]:
                    if f.t >= start and (predicate is None or predicate(f.values)):
                        return f
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                self._cond.wait(remaining)

    def stop(self) -> None:
        """Listener hook, called by the notifier when it stops: nothing to release."""

    def close(self) -> None:
        """Stop listening (the bus stays open: its owner shuts it down)."""
        self._notifier.stop()
