"""The driver's links to a lower computer: a live bus that survives its device, or a replay.

:class:`BusLink` wraps any python-can bus (serial framing, slcan, SocketCAN, udp_multicast).
Any receive or transmit error (a USB adapter unplugged, the emulator behind a pty killed, an
interface taken down) closes the bus and reports the link down (``on_down``: the driver core
shows ``lost`` at once); the bus is then reopened every ``reopen_period`` until it opens, and
frames flow again: no respawn. :class:`ReplayLink` feeds a recorded log instead.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from lowerbase.clock import Clock, RealClock, SimClock
from lowerbase.errors import ConfigError, LowerbaseError
from lowerbase.protocol.codec import default_codec
from lowerbase.transport import describe, is_catalog_frame, open_bus

log = logging.getLogger(__name__)

#: python-can log formats that --replay reads (can.LogReader picks the reader by suffix)
REPLAY_SUFFIXES = (".log", ".asc", ".blf", ".csv", ".trc", ".mf4")

FrameSink = Callable[[int, bytes], None]
DownSink = Callable[[str], None]
Opener = Callable[[dict[str, Any]], Any]


class BusLink:
    """A python-can bus that is closed on any error and reopened every ``reopen_period``."""

    def __init__(
        self, config: dict[str, Any], reopen_period: float = 1.0, *,
        opener: Opener | None = None, clock: Clock | None = None,
    ) -> None:
        self.config = config
        self.reopen_period = reopen_period
        self.description = describe(config)
        self._open_bus: Opener = opener or open_bus
        self.clock = clock or RealClock()
        self._bus: Any = self._open_bus(config)  # the first failure is the user's: raise it
        self._failed: str | None = None  # a transmit error: the reader closes the bus
        self._next_open = -math.inf
        self._last_error_log = -math.inf
        self.tx_errors = 0
        self.rx_errors = 0
        self.reopens = 0
        self.frames = 0

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
             timeout: float = 0.1) -> float:
        """One step of the reader: reopen if due, or receive one frame within ``timeout``.

        Returns how long the caller should wait before the next step (0: at once).
        """
        if self._failed is not None:
            self._close(self._failed, on_down)
        if self._bus is None:
            now = self.clock.now()
            if now < self._next_open:
                return self._next_open - now
            try:
                self._bus = self._open_bus(self.config)
            except (LowerbaseError, Exception) as exc:
                self._next_open = now + self.reopen_period
                self._log_error(f"cannot reopen: {exc}")
                return self.reopen_period
            self.reopens += 1
            log.warning("bus reopened: %s", self.description)
            return 0.0
        try:
            msg = self._bus.recv(timeout)
        except Exception as exc:  # any backend's error: serial, slcan, socket, our own
            self.rx_errors += 1
            self._close(f"receive failed: {exc or type(exc).__name__}", on_down)
            return self.reopen_period
        if msg is not None and is_catalog_frame(msg):
            self.frames += 1
            on_frame(msg.arbitration_id, bytes(msg.data))
        return 0.0

    def run_reader(self, on_frame: FrameSink, stop: threading.Event,
                   on_down: DownSink | None = None) -> None:
        """Feed ``on_frame`` until ``stop`` is set; the bus is reopened after any error."""
        while not stop.is_set():
            delay = self.poll(on_frame, on_down)
            if delay > 0:
                stop.wait(delay)

    def close(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            with contextlib.suppress(Exception):
                bus.shutdown()


class ReplayLink:
    """Frames from a python-can log file (.log, .asc, .blf, ...) with their original timing.

    What the driver sends goes nowhere (it is counted): a replay reproduces what the driver
    made of a recorded run, it does not drive anything. A recording that starts after the
    driver's parameter exchange (no ParameterResponse in it: found by a scan at construction
    that stops at the first one) would leave the driver ``configuring`` for good; ``advice``
    then says so in one line. Given ``parameters`` (wire names, e.g. from a robot profile),
    the link answers the driver's parameter reads itself, as the lower computer did, so the
    driver configures and the recording's odometry is replayed; a recording that has the
    exchange is replayed as it is and ``parameters`` are not used.

    With a :class:`~lowerbase.clock.SimClock` the replay does not wait: the clock is advanced
    to each frame's recorded time instead (tests, batch runs).
    """

    def __init__(
        self, path: str | Path, *, finished: Callable[[], None] | None = None,
        parameters: Mapping[str, float] | None = None, clock: Clock | None = None,
    ) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise ConfigError(f"--replay: no such file: {self.path}")
        if self.path.suffix.lower() not in REPLAY_SUFFIXES:
            raise ConfigError(f"--replay: {self.path.name}: not a python-can log "
                              f"({', '.join(REPLAY_SUFFIXES)})")
        self.description = f"replay of {self.path}"
        self.finished = finished
        self.clock = clock
        self.sent = 0
        self.frames = 0
        codec = default_codec()
        self._request = codec.message("ParameterRequest")
        self._response = codec.message("ParameterResponse")
        self._names: dict[int, str] = dict(self._request.signal("Index").choices or {})
        self.parameters = dict(parameters or {})
        #: the recording holds the lower computer's ParameterResponse frames
        self.has_parameter_exchange = self._scan_for(self._response.frame_id)
        #: the link answers the driver's parameter reads from ``parameters``
        self.answering = bool(self.parameters) and not self.has_parameter_exchange
        self.answered = 0
        self._answers: deque[tuple[int, bytes]] = deque()

    @property
    def advice(self) -> str | None:
        """One line for the user about the parameters of this replay, or None."""
        if self.has_parameter_exchange:
            if self.parameters:
                return (f"{self.path.name} has the parameter exchange: the recorded "
                        "parameters are used, --replay-profile/--replay-param ignored")
            return None
        if self.answering:
            return (f"{self.path.name} starts after the driver's parameter exchange: the "
                    "driver's parameter reads are answered with the given parameters")
        return (f"{self.path.name} starts after the driver's parameter exchange (no "
                "ParameterResponse in it): the driver would stay 'configuring' without "
                "odometry; pass --replay-profile FILE (or 'default') and/or --replay-param "
                "NAME=VALUE to replay it with those parameters")

    def _scan_for(self, frame_id: int) -> bool:
        import can

        try:
            with can.LogReader(str(self.path)) as reader:
                return any(m.arbitration_id == frame_id and is_catalog_frame(m)
                           for m in reader)
        except Exception:  # a garbled log: run_reader says so when it gets there
            return False

    def send(self, frame_id: int, data: bytes) -> None:
        self.sent += 1
        if not self.answering or frame_id != self._request.frame_id:
            return
        try:
            request = self._request.decode(data, strict=False)
        except LowerbaseError:
            return
        index = int(request["Index"])
        name = self._names.get(index)
        if int(request["Op"]) != 0 or name not in self.parameters:
            return  # writes, and parameters not given, go nowhere like every command
        self._answers.append((self._response.frame_id, self._response.encode(
            {"Index": index, "Op": 0, "Result": 0, "Value": self.parameters[name]})))

    def _deliver_answers(self, on_frame: FrameSink) -> None:
        while self._answers:
            frame_id, data = self._answers.popleft()
            self.answered += 1
            on_frame(frame_id, data)

    def _messages(self, reader: Any) -> Iterator[Any]:
        import can

        if not isinstance(self.clock, SimClock):
            yield from can.MessageSync(reader, timestamps=True, skip=5.0)
            return
        start, first = self.clock.now(), None
        for msg in reader:
            first = msg.timestamp if first is None else first
            due = start + max(msg.timestamp - first, 0.0)
            if due > self.clock.now():
                self.clock.advance(due - self.clock.now())
            yield msg

    def run_reader(self, on_frame: FrameSink, stop: threading.Event,
                   on_down: DownSink | None = None) -> None:
        import can

        try:
            with can.LogReader(str(self.path)) as reader:
                for msg in self._messages(reader):
                    if stop.is_set():
                        return
                    self._deliver_answers(on_frame)
                    if not is_catalog_frame(msg):
                        continue
                    self.frames += 1
                    on_frame(msg.arbitration_id, bytes(msg.data))
        except Exception as exc:  # a truncated or garbled log: say so, do not crash the node
            log.error("replay of %s stopped: %s", self.path, exc)
        log.info("replay finished: %d frames from %s", self.frames, self.path)
        if self.finished is not None:
            self.finished()

    def close(self) -> None:
        pass
