"""The driver's links to a lower computer: a live bus that survives its device, or a replay.

:class:`BusLink` wraps any python-can bus (serial framing, slcan, SocketCAN, udp_multicast).
Any receive or transmit error (a USB adapter unplugged, the emulator behind a pty killed, an
interface taken down) closes the bus and reports the link down (``on_down``: the driver core
shows ``lost`` at once); the bus is then reopened every ``reopen_period`` until it opens, and
frames flow again: no respawn. A serial device that does not exist yet at start (the adapter
not plugged in, the emulator's pty started second) is waited for the same way: one line says
so, and the device is opened when it appears. :class:`ReplayLink` (lowerbase.driver.replay) feeds a
recorded log instead.

A BusLink listens only to what the lower computer sends (:func:`listen_to_lower`) unless the
configuration names its own ``can_filters``: on udp_multicast (and SocketCAN) other devices'
frames on a shared bus are dropped in the kernel and never wake the driver.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from lowerbase.clock import CATCH_UP, SLIP_WARN_EVERY, Clock, RealClock, WarnLimiter
from lowerbase.driver.replay import REPLAY_SUFFIXES, ReplayLink
from lowerbase.errors import LowerbaseError
from lowerbase.protocol.codec import default_codec
from lowerbase.transport import describe, is_catalog_frame, open_bus

log = logging.getLogger(__name__)

__all__ = ["REPLAY_SUFFIXES", "BusLink", "ReplayLink", "missing_device"]


FrameSink = Callable[[int, bytes], None]
DownSink = Callable[[str], None]
Opener = Callable[[dict[str, Any]], Any]

#: interfaces whose channel is a serial device (a file, possibly ``DEVICE@BAUD`` for slcan)
SERIAL_INTERFACES = ("lowerbase_serial", "slcan", "serial")

#: compares the whole ID and ignores the extended flag (a foreign extended frame on a catalog
#: ID still arrives, and is dropped as not a catalog frame)
FULL_ID_MASK = 0x1FFFFFFF


def filters_in_kernel(bus: object) -> bool:
    """Whether ``bus`` drops filtered frames before they reach the process (udp_multicast's
    socket filter, SocketCAN's CAN_RAW_FILTER). Other buses filter in python-can, where
    ``recv(0)`` returns None at a filtered frame with more waiting: they are left unfiltered."""
    return type(bus).__name__ in ("GroupOnlyMulticastBus", "SocketcanBus")


def upper_listens_to() -> list[int]:
    """The IDs the driver reads: every frame the lower computer sends."""
    return sorted(m.frame_id for m in default_codec() if "Lower" in m.senders)


def listen_to_lower(bus: Any) -> bool:
    """Set ``bus``'s filters to :func:`upper_listens_to` unless it has filters already or
    cannot filter in the kernel (:func:`filters_in_kernel`); True when set."""
    set_filters = getattr(bus, "set_filters", None)
    if set_filters is None or getattr(bus, "filters", None) or not filters_in_kernel(bus):
        return False
    set_filters([{"can_id": i, "can_mask": FULL_ID_MASK} for i in upper_listens_to()])
    return True


def missing_device(config: dict[str, Any]) -> str | None:
    """The serial device file ``config`` names when it does not exist (yet), else None
    (not a serial interface, a pyserial URL, a ``pty:`` the bus creates, a device that is
    there). A dangling link (an emulator's old pty link) does not exist."""
    if config.get("interface") not in SERIAL_INTERFACES:
        return None
    channel = str(config.get("channel") or "")
    if config.get("interface") == "slcan":
        channel = channel.split("@", 1)[0]
    if "://" in channel or channel == "pty" or channel.startswith("pty:") or "/" not in channel:
        return None
    return None if os.path.exists(channel) else channel


#: [s] a frame's receive stamp older than this (or in the future) is not believed: a bus whose
#: timestamps are not the wall clock's (a replay, an adapter's own counter: off by years). A
#: reader on a busy host can be seconds behind its socket (beside 12 busy processes driver_base
#: was over 5 s behind); its stamps must still count, or its Heartbeats look like reboots
MAX_RECEIVE_AGE = 60.0


def receive_age(msg: Any, wall_now: float) -> float:
    """[s] how long ``msg`` waited since the bus received it (its ``timestamp``: the kernel's
    receive time on SocketCAN and udp_multicast), 0.0 when the stamp is missing or unbelievable.
    A reader that falls behind (a busy host) then still knows when each frame arrived."""
    stamp = getattr(msg, "timestamp", None)
    if not isinstance(stamp, (int, float)) or not math.isfinite(stamp):
        return 0.0
    age = wall_now - float(stamp)
    return age if 0.0 <= age <= MAX_RECEIVE_AGE else 0.0


#: [s] a frame handed on this long after its bus received it was handled late: the reader is
#: behind its bus (as far as a paced emulator may run behind before its time slips)
LATE_HANDLING = CATCH_UP


class HandlingLag:
    """How far behind its bus a reader runs, said rather than hidden: each frame handled more
    than :data:`LATE_HANDLING` after the bus received it is counted (``stats
    ["frames_handled_late"]``; the latest of them in ``worst`` [s]) and warned of at most every
    :data:`~lowerbase.clock.SLIP_WARN_EVERY` s. Such frames keep their receive stamps, so the
    odometry stays right; what comes late is everything the node sends from them."""

    def __init__(self, stats: Counter[str], name: str = "driver_base") -> None:
        self.stats = stats
        self.name = name
        self.worst = 0.0  #: [s] the latest frame so far
        self._warn = WarnLimiter(SLIP_WARN_EVERY)

    def handled(self, age: float, now: float) -> None:
        """A frame handed on ``age`` [s] after its reception, at wall time ``now`` [s]."""
        if not age > LATE_HANDLING:
            return
        self.stats["frames_handled_late"] += 1
        self.worst = max(self.worst, age)
        said = self._warn.take(now, age)
        if said is not None:
            log.warning("%s is behind its bus (a busy host): %d frame(s) handled up to %.3f s "
                        "after they were received; what it publishes from them comes that late "
                        "(%d late in all)", self.name, *said, self.stats["frames_handled_late"])


class BusLink:
    """A python-can bus that is closed on any error and reopened every ``reopen_period``.

    ``last_age`` is :func:`receive_age` of the frame being handed to ``on_frame``, and
    ``last_received`` its receive time on the wall clock (``time.time``), None when not known.
    A serial device that does not exist at start (:func:`missing_device`) is waited for:
    ``announce`` (a line for the user; default: a warning in the log) says so once, and that
    it is open when it appears; any other failure to open at start is raised."""

    def __init__(
        self, config: dict[str, Any], reopen_period: float = 1.0, *,
        opener: Opener | None = None, clock: Clock | None = None, catalog_filter: bool = True,
        announce: Callable[[str], None] | None = None,
    ) -> None:
        self.config = config
        #: listen to the lower computer's IDs only (unless ``config`` has ``can_filters``)
        self.catalog_filter = catalog_filter and not config.get("can_filters")
        self.reopen_period = reopen_period
        self.description = describe(config)
        self._open_bus: Opener = opener or open_bus
        self.clock = clock or RealClock()
        self._announce = announce or log.warning
        #: the serial device waited for (it did not exist at start), until it opens
        self.waiting_for = missing_device(config)
        self._bus: Any = None
        if self.waiting_for is None:
            self._bus = self._open(config)  # the first failure is the user's: raise it
        else:
            self._announce(f"waiting for {self.waiting_for} to appear (looking every "
                           f"{reopen_period:g} s)")
        self._failed: str | None = None  # a transmit error: the reader closes the bus
        self._next_open = -math.inf
        self._last_error_log = -math.inf
        self.tx_errors = 0
        self.rx_errors = 0
        self.reopens = 0
        self.frames = 0
        self.last_age = 0.0  #: [s, wall] since the frame now in ``on_frame`` was received
        #: [s, wall clock] when the bus received it (None: its stamp is not believed)
        self.last_received: float | None = None

    def _open(self, config: dict[str, Any]) -> Any:
        bus = self._open_bus(config)
        if self.catalog_filter:
            listen_to_lower(bus)
        return bus

    @property
    def is_open(self) -> bool:
        return self._bus is not None and self._failed is None

    def send(self, frame_id: int, data: bytes) -> None:
        import can

        bus = self._bus
        if bus is None or self._failed is not None:
            self.tx_errors += 1
            return
        try:
            bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
        except Exception as exc:  # any backend's error: the device is gone or broken
            self.tx_errors += 1
            self._failed = f"transmit failed: {exc or type(exc).__name__}"

    def _log_error(self, text: str) -> None:
        now = time.monotonic()
        if now - self._last_error_log >= 5.0:
            self._last_error_log = now
            log.warning("%s (%s)", text, self.description)

    def _close(self, why: str, on_down: DownSink | None) -> None:
        bus, self._bus, self._failed = self._bus, None, None
        if bus is not None:
            with contextlib.suppress(Exception):
                bus.shutdown()
        self._next_open = self.clock.now() + self.reopen_period
        self._log_error(f"{why}; reopening the bus every {self.reopen_period:g} s")
        if on_down is not None:
            on_down(why)

    def poll(self, on_frame: FrameSink, on_down: DownSink | None = None,
             timeout: float = 0.1, on_idle: Callable[[], None] | None = None) -> float:
        """One step of the reader: reopen if due, or receive one frame within ``timeout``.

        Returns how long the caller should wait before the next step (0: at once).
        """
        if self._failed is not None:
            self._close(self._failed, on_down)
        if self._bus is None:
            now = self.clock.now()
            if now < self._next_open:
                return self._next_open - now
            if self.waiting_for is not None and missing_device(self.config) is not None:
                self._next_open = now + self.reopen_period  # still not there: said already
                return self.reopen_period
            try:
                self._bus = self._open(self.config)
            except (LowerbaseError, Exception) as exc:
                self._next_open = now + self.reopen_period
                self._log_error(f"cannot {'open' if self.waiting_for else 'reopen'}: {exc}")
                return self.reopen_period
            if self.waiting_for is not None:
                self._announce(f"{self.waiting_for} appeared: {self.description} open")
                self.waiting_for = None
            else:
                self.reopens += 1
                log.warning("bus reopened: %s", self.description)
            return 0.0
        try:
            msg = self._bus.recv(timeout)
        except Exception as exc:  # any backend's error: serial, slcan, socket, our own
            self.rx_errors += 1
            self._close(f"receive failed: {exc or type(exc).__name__}", on_down)
            return self.reopen_period
        if msg is None:
            if on_idle is not None:  # listened for ``timeout``: nothing is waiting
                on_idle()
        elif is_catalog_frame(msg):
            self.frames += 1
            wall = time.time()
            self.last_age = receive_age(msg, wall)
            self.last_received = wall - self.last_age if self.last_age > 0.0 else None
            on_frame(msg.arbitration_id, bytes(msg.data))
        return 0.0

    def run_reader(self, on_frame: FrameSink, stop: threading.Event,
                   on_down: DownSink | None = None,
                   on_idle: Callable[[], None] | None = None) -> None:
        """Feed ``on_frame`` until ``stop`` is set; the bus is reopened after any error.
        ``on_idle`` is called when a receive found nothing waiting."""
        while not stop.is_set():
            delay = self.poll(on_frame, on_down, on_idle=on_idle)
            if delay > 0:
                stop.wait(delay)

    def close(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            with contextlib.suppress(Exception):
                bus.shutdown()
