"""The legged suite's view of the four leg buses: what the lower computer sends, by (bus, ID),
on one time base, and raw sends.

Two links with one interface. :class:`BusesLink` is the real thing: four python-can buses
(leg bus k = FR, FL, RR, RL), a reader thread, ``time.monotonic``, frames timestamped by the
bus. :class:`SimLink` runs the emulator's :class:`~lowerbase.legged.lower.LeggedLower` on a
:class:`~lowerbase.clock.SimClock`: ``wait`` steps it, frames cross at once, so the suite is
deterministic and runs as fast as the CPU allows (the tests' ground truth for the injected
defects).

The actuator traffic (IDs 0..3: 6,000 frames/s per bus) is kept only while
:attr:`LeggedLink.capture` is on, so a run's memory stays bounded; the body frames are always
kept. Frames the upper side sends itself are not heard (a CAN controller does not receive its
own frames).
"""

from __future__ import annotations

import contextlib
import math
import selectors
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

import can

from lowerbase.clock import SimClock
from lowerbase.legged.lower import LeggedLower
from lowerbase.legged.profile import LeggedProfile
from lowerbase.protocol.legged import N_BUSES
from lowerbase.transport import is_catalog_frame

#: the actuator traffic's IDs (MotorReply and the three commands)
ACTUATOR_IDS = frozenset({0, 1, 2, 3})
#: [s] a bus timestamp older than this (or in the future) is not trusted: reception time
MAX_STAMP_AGE = 2.0
#: [s] the longest a wait lets the reader thread catch up
FLUSH_TIMEOUT = 2.0


@dataclass(frozen=True)
class LegFrame:
    t: float  #: arrival on the link's time base [s] (the bus timestamp where it is sane)
    stamp: float  #: the bus's timestamp [s] (kernel time on udp_multicast and SocketCAN)
    data: bytes


class LeggedLink(ABC):
    """Frames of the lower computer on four buses, and sends to it (see the module)."""

    def __init__(self) -> None:
        self._frames: dict[tuple[int, int], list[LegFrame]] = {}
        self._lock = threading.Lock()
        self.capture = False  #: keep the actuator traffic too
        self.dropped_uncaptured = 0

    def record(self, bus: int, frame_id: int, data: bytes, t: float, stamp: float) -> None:
        if frame_id in ACTUATOR_IDS and not self.capture:
            self.dropped_uncaptured += 1
            return
        with self._lock:
            self._frames.setdefault((bus, frame_id), []).append(LegFrame(t, stamp, data))

    def frames(self, bus: int, frame_id: int, since: float = -math.inf,
               until: float = math.inf) -> list[LegFrame]:
        with self._lock:
            return [f for f in self._frames.get((bus, frame_id), ()) if since <= f.t <= until]

    def latest(self, bus: int, frame_id: int) -> LegFrame | None:
        with self._lock:
            got = self._frames.get((bus, frame_id))
            return got[-1] if got else None

    def heard_anything(self) -> bool:
        with self._lock:
            return bool(self._frames) or self.dropped_uncaptured > 0

    def forget_actuator_traffic(self) -> None:
        """Drop the kept actuator frames (after a check has looked at them)."""
        with self._lock:
            for key in [k for k in self._frames if k[1] in ACTUATOR_IDS]:
                del self._frames[key]

    @abstractmethod
    def now(self) -> float: ...

    @abstractmethod
    def wait(self, seconds: float) -> None:
        """Let ``seconds`` pass (frames arrive meanwhile)."""

    @abstractmethod
    def send(self, bus: int, frame_id: int, data: bytes) -> None: ...

    def flush(self, until: float) -> None:  # noqa: B027  (nothing to wait for by default)
        """Return once every frame that arrived before ``until`` is recorded."""

    @abstractmethod
    def close(self) -> None:
        """Release what the link holds."""


class BusesLink(LeggedLink):
    """Four python-can buses, read by one thread (``time.monotonic`` time base)."""

    def __init__(self, buses: Sequence[can.BusABC]) -> None:
        super().__init__()
        if len(buses) != N_BUSES:
            raise ValueError(f"the legged robot has {N_BUSES} buses, not {len(buses)}")
        self.buses = list(buses)
        #: bus timestamps (time.time base on python-can's interfaces) -> time.monotonic
        self._offset = time.monotonic() - time.time()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._drained = threading.Condition()
        self._drained_at = -math.inf  #: every frame that arrived before this is recorded
        self._thread = threading.Thread(target=self._read, name="legged-conformance",
                                         daemon=True)
        self._thread.start()

    def _read(self) -> None:
        selector = selectors.DefaultSelector()
        polled = []
        for k, bus in enumerate(self.buses):
            try:
                fd = bus.fileno()
            except (NotImplementedError, AttributeError):
                fd = -1
            if fd >= 0:
                selector.register(fd, selectors.EVENT_READ, k)
            else:
                polled.append(k)
        try:
            while not self._stop.is_set():
                started = time.monotonic()
                ready = [key.data for key, _ in selector.select(0.001 if polled else 0.05)]
                for k in [*ready, *polled]:
                    self._drain(k)
                with self._drained:
                    self._drained_at = started
                    self._drained.notify_all()
        finally:
            selector.close()

    def _drain(self, k: int) -> None:
        bus = self.buses[k]
        while True:
            try:
                msg = bus.recv(0.0)
            except can.CanError:
                return
            if msg is None:
                return
            if is_catalog_frame(msg):
                now = time.monotonic()
                # the bus's (kernel) timestamp on the monotonic time base: this thread may
                # run behind at 24,000 frames/s, the timestamp does not
                t = (msg.timestamp or 0.0) + self._offset
                if not now - MAX_STAMP_AGE <= t <= now:
                    t = now
                self.record(k, msg.arbitration_id, bytes(msg.data), t, msg.timestamp or now)

    def now(self) -> float:
        return time.monotonic()

    def wait(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)
        self.flush(time.monotonic())

    def flush(self, until: float) -> None:
        with self._drained:
            self._drained.wait_for(lambda: self._drained_at >= until or self._stop.is_set()
                                   or not self._thread.is_alive(), timeout=FLUSH_TIMEOUT)

    def send(self, bus: int, frame_id: int, data: bytes) -> None:
        with self._send_lock:
            self.buses[bus].send(can.Message(arbitration_id=frame_id, data=data,
                                             is_extended_id=False))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)


class SimLink(LeggedLink):
    """The emulated lower computer on a simulated clock (``wait`` steps it)."""

    def __init__(self, profile: LeggedProfile | None = None, *, defects: tuple[str, ...] = (),
                 bms: bool = True, soc: float = 80.0) -> None:
        from lowerbase.legged.runner import legged_bms

        super().__init__()
        profile = profile or LeggedProfile()
        self.clock = SimClock()
        self.lower = LeggedLower(profile, self.clock, self._from_lower,
                                 bms=legged_bms(profile, soc) if bms else None,
                                 defects=defects)

    def _from_lower(self, bus: int, frame_id: int, data: bytes) -> None:
        t = self.clock.now()
        self.record(bus, frame_id, data, t, t)

    def now(self) -> float:
        return self.clock.now()

    def wait(self, seconds: float) -> None:
        end = self.clock.now() + seconds - 1e-9
        while self.clock.now() < end:
            self.lower.step()
            self.clock.advance(self.lower.dt)

    def send(self, bus: int, frame_id: int, data: bytes) -> None:
        if not 0 <= bus < N_BUSES:
            raise ValueError(f"no leg bus {bus}")
        self.lower.receive(bus, frame_id, bytes(data))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.lower.shutdown()
