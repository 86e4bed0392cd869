"""Notice two lower computers on one bus, from the Heartbeats they send.

A lower computer sends one Heartbeat per cycle (chassis.dbc: 500 ms) with its Uptime, its
BootCounter and a rolling Counter. One lower computer's Heartbeats form one *stream*: the same
BootCounter, an Uptime that advances as the receiver's clock does (within ``tolerance``), and
a Counter that advances by the number of cycles the Uptime advanced (mod 16). Heartbeats that
fit no stream start a new one.

Two lower computers on one bus (two emulators, an emulator beside real firmware) are two
streams that are *both confirmed* (``confirm`` Heartbeats each), *both alive* (each heard
within ``stale``), and *interleaved* (each was heard after the other one started). This is
what a reboot is not (the old stream stops before the new one starts) and what a single
forged or garbled Heartbeat is not (one frame, never confirmed). Two started at the same
moment send identical Heartbeats: a confirmed stream whose Heartbeats arrive twice
(``confirm`` times) is two lower computers as well.

Usage, on any side of the bus::

    monitor = PeerMonitor()
    if monitor.on_frame(frame_id, data, now):   # True once, when the second one shows up
        log.warning(monitor.warning)

A lower computer (the emulator) counts itself: it passes what it sends to ``on_sent``, and
its own Heartbeats heard back (udp_multicast loops them back) are recognised and skipped,
so any other confirmed stream is a second lower computer. Frames that are not Heartbeats,
and Heartbeats that do not decode, are ignored (their owner counts malformed frames).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from lowerbase.errors import ProtocolError
from lowerbase.protocol.codec import Codec, default_codec

__all__ = ["HeartbeatStream", "PeerMonitor"]


@dataclass
class HeartbeatStream:
    """The Heartbeats of one lower computer, as far as they can be told apart."""

    boot: int
    uptime: float  #: of the latest Heartbeat [s]
    counter: int  #: of the latest Heartbeat
    first: float  #: receive time of the first Heartbeat [s]
    last: float  #: receive time of the latest Heartbeat [s]
    count: int = 1
    duplicates: int = 0  #: Heartbeats heard twice: two lower computers in lockstep
    overruns: int = 0  #: of the latest Heartbeat (its sender's slips behind real time, mod 16)

    def describe(self) -> str:
        return f"BootCounter {self.boot}, uptime {self.uptime:.1f} s"


class PeerMonitor:
    """Says when Heartbeats of two lower computers share one bus (see the module docstring)."""

    def __init__(
        self, codec: Codec | None = None, *, confirm: int = 3, stale: float | None = None,
        tolerance: float = 0.3,
    ) -> None:
        codec = codec or default_codec()
        heartbeat = codec.message("Heartbeat")
        self.heartbeat_id = heartbeat.frame_id
        self._decode = heartbeat.decode
        self.period = heartbeat.cycle_time or 0.5
        self.confirm = confirm
        self.stale = 4.0 * self.period if stale is None else stale
        self.tolerance = tolerance
        self.streams: list[HeartbeatStream] = []
        self._own: deque[bytes] = deque(maxlen=8)
        self._own_last = -math.inf
        self.conflict = False  #: two lower computers were seen (stays True)
        self.warning = ""  #: the one-line warning, once ``conflict``

    def on_sent(self, frame_id: int, data: bytes, stamp: float) -> None:
        """A frame this side sent (only a lower computer needs to call this)."""
        if frame_id == self.heartbeat_id:
            self._own.append(bytes(data))
            self._own_last = stamp

    def on_frame(self, frame_id: int, data: bytes, stamp: float) -> bool:
        """A received frame; True exactly once: when two lower computers are first seen."""
        if frame_id != self.heartbeat_id or bytes(data) in self._own:
            return False
        try:
            values = self._decode(bytes(data), strict=False)
        except ProtocolError:
            return False
        boot, counter = int(values["BootCounter"]), int(values["Counter"])
        uptime, overruns = float(values["Uptime"]), int(values.get("Overruns", 0))
        self.streams = [s for s in self.streams if stamp - s.last <= self.stale]
        stream = next((s for s in self.streams
                       if self._fits(s, boot, uptime, counter, stamp, overruns)), None)
        if stream is None:
            self.streams.append(HeartbeatStream(boot, uptime, counter, stamp, stamp,
                                                overruns=overruns))
        elif uptime == stream.uptime:  # the same Heartbeat twice: a second sender in step
            stream.duplicates += 1
        else:
            stream.uptime, stream.counter, stream.last = uptime, counter, stamp
            stream.overruns = overruns
            stream.count += 1
        return self._check(stamp)

    @property
    def lower_computers(self) -> int:
        """How many lower computers are on the bus now, as far as this monitor knows."""
        return len(self._confirmed(self.streams[-1].last if self.streams else -math.inf))

    def _fits(self, s: HeartbeatStream, boot: int, uptime: float, counter: int,
              stamp: float, overruns: int = 0) -> bool:
        if boot != s.boot:
            return False
        if uptime == s.uptime:
            return counter == s.counter
        du, dt = uptime - s.uptime, stamp - s.last
        # a sender that fell behind real time says so (Overruns moved): its Uptime then
        # advanced less than the receiver's clock
        slipped = overruns != s.overruns and 0 < du < dt
        if du <= 0 or (abs(du - dt) > self.tolerance + 0.05 * dt and not slipped):
            return False
        return (counter - s.counter) % 16 == round(du / self.period) % 16

    def _confirmed(self, now: float) -> list[HeartbeatStream]:
        return [s for s in self.streams if s.count >= self.confirm and now - s.last <= self.stale]

    def _check(self, now: float) -> bool:
        if self.conflict:
            return False
        alive = self._confirmed(now)
        pairs = [(a, b) for i, a in enumerate(alive) for b in alive[i + 1:]
                 if a.last > b.first and b.last > a.first]
        twins = [s for s in alive if s.duplicates >= self.confirm]
        if pairs:
            a, b = pairs[0]
            seen = f"{a.describe()}; {b.describe()}"
        elif twins:
            seen = f"two in step, each Heartbeat twice: {twins[0].describe()}"
        elif alive and now - self._own_last <= self.stale:
            seen = f"this one and one with {alive[0].describe()}"
        else:
            return False
        self.conflict = True
        self.warning = (f"two lower computers on one bus (Heartbeats from {seen}): commands "
                        "reach both; stop one (another lowerbase emulate, or real firmware on "
                        "the same bus), or give each its own bus or channel")
        return True
