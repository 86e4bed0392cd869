"""``lowerbase driver --replay FILE``: a recorded log fed to the driver instead of a bus.

The file is read by :mod:`lowerbase.transport.logfiles`, as ``lowerbase decode`` reads it: a text
line that is not a frame (also one that is not UTF-8) is skipped and reported with file:line;
a corrupt binary file, or a .blf shorter than its header says, ends the replay with an error
(``error``: the command exits non-zero).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

from lowerbase.clock import Clock, SimClock
from lowerbase.errors import ConfigError, LowerbaseError
from lowerbase.protocol.codec import default_codec
from lowerbase.transport.logfiles import (
    MAX_REPORTED_LINES,
    BadLine,
    Corrupt,
    Frame,
    Item,
    frames_from_log,
)

log = logging.getLogger(__name__)

#: python-can log formats that --replay reads (python-can picks the reader by suffix)
REPLAY_SUFFIXES = (".log", ".asc", ".blf", ".csv", ".trc", ".mf4")
#: [s] a longer pause between two recorded frames is shortened to this (as can.MessageSync)
MAX_PAUSE = 5.0

FrameSink = Callable[[int, bytes], None]
DownSink = Callable[[str], None]


class ReplayLink:
    """Frames from a python-can log file (.log, .asc, .blf, ...) with their original timing.

    What the driver sends goes nowhere (it is counted): a replay reproduces what the driver
    made of a recorded run, it does not drive anything. The file is scanned once at
    construction: a recording that starts after the driver's parameter exchange (no
    ParameterResponse in it) would leave the driver ``configuring`` for good, and ``advice``
    says so in one line, but only for a file that was read fine; for a corrupt or truncated one
    it says that instead (``scan_error``). Given ``parameters`` (wire names, e.g. from a robot
    profile), the link answers the driver's parameter reads itself, as the lower computer did,
    so the driver configures and the recording's odometry is replayed; a recording that has the
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
        #: text lines that were not frames, skipped (while replaying)
        self.skipped_lines = 0
        #: why the replay stopped before the end of the file (corrupt, truncated), else None
        self.error: str | None = None
        codec = default_codec()
        self._request = codec.message("ParameterRequest")
        self._response = codec.message("ParameterResponse")
        self._names: dict[int, str] = dict(self._request.signal("Index").choices or {})
        self.parameters = dict(parameters or {})
        #: what the scan found wrong with the file (it is replayed up to there), or None
        self.scan_error: str | None = None
        #: the recording holds the lower computer's ParameterResponse frames
        self.has_parameter_exchange = self._scan()
        #: the link answers the driver's parameter reads from ``parameters``
        self.answering = bool(self.parameters) and not self.has_parameter_exchange
        self.answered = 0
        self._answers: deque[tuple[int, bytes]] = deque()

    @property
    def advice(self) -> str | None:
        """One line for the user about this replay (its file, its parameters), or None."""
        if self.has_parameter_exchange:
            if self.parameters:
                return (f"{self.path.name} has the parameter exchange: the recorded "
                        "parameters are used, --replay-profile/--replay-param ignored")
            return None
        if self.scan_error is not None:
            return f"{self.scan_error}: the replay stops there"
        if self.answering:
            return (f"{self.path.name} starts after the driver's parameter exchange: the "
                    "driver's parameter reads are answered with the given parameters")
        return (f"{self.path.name} starts after the driver's parameter exchange (no "
                "ParameterResponse in it): the driver would stay 'configuring' without "
                "odometry; pass --replay-profile FILE (or 'default') and/or --replay-param "
                "NAME=VALUE to replay it with those parameters")

    def _scan(self) -> bool:
        """Read the whole file once: whether it has a ParameterResponse; ``scan_error``."""
        found = False
        for item in frames_from_log(self.path):  # ConfigError: cannot be opened at all
            if isinstance(item, Corrupt):
                self.scan_error = f"{item.where}: corrupt file: {item.reason}"
            elif isinstance(item, Frame) and not item.kind and \
                    item.frame_id == self._response.frame_id:
                found = True
        return found

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

    def _paced(self, items: Iterator[Item], stop: threading.Event) -> Iterator[Item]:
        """The items at their recorded pace (a SimClock is advanced instead of waited on)."""
        clock = self.clock if isinstance(self.clock, SimClock) else None
        sim = clock is not None
        start = clock.now() if clock is not None else time.monotonic()
        offset = 0.0  # [s] of the recording's time since its first frame (pauses shortened)
        previous: float | None = None
        for item in items:
            if isinstance(item, Frame) and item.timestamp is not None:
                if previous is not None:
                    pause = max(item.timestamp - previous, 0.0)
                    offset += pause if sim else min(pause, MAX_PAUSE)
                previous = item.timestamp
                if clock is not None:
                    if start + offset > clock.now():
                        clock.advance(start + offset - clock.now())
                else:
                    wait = start + offset - time.monotonic()
                    if wait > 0 and stop.wait(wait):
                        return
            yield item

    def run_reader(self, on_frame: FrameSink, stop: threading.Event,
                   on_down: DownSink | None = None,
                   on_idle: Callable[[], None] | None = None) -> None:
        """Feed the file's frames at their pace (``on_idle``: unused, a replay never waits on a
        bus; the live link's signature)."""
        try:
            for item in self._paced(frames_from_log(self.path), stop):
                if stop.is_set():
                    return
                self._deliver_answers(on_frame)
                if isinstance(item, BadLine):
                    self.skipped_lines += 1
                    if self.skipped_lines <= MAX_REPORTED_LINES:
                        log.warning("%s: not a frame, skipped: %r", item.where, item.text[:80])
                elif isinstance(item, Corrupt):
                    self.error = f"{item.where}: corrupt file: {item.reason}"
                    log.error("replay stopped: %s", self.error)
                elif not item.kind:  # extended, remote, error, FD: never a catalog frame
                    self.frames += 1
                    on_frame(item.frame_id, item.data)
        except ConfigError as exc:  # the file went away or became unreadable meanwhile
            self.error = str(exc)
            log.error("replay stopped: %s", exc)
        skipped = f", {self.skipped_lines} line(s) skipped" if self.skipped_lines else ""
        log.info("replay finished: %d frames from %s%s", self.frames, self.path, skipped)
        if self.finished is not None:
            self.finished()

    def close(self) -> None:
        pass
