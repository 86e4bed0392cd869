"""``lowerbase record``: record a live bus to a file other tools open (candump, ASC, BLF).

A thin layer over python-can's writers (``can.Logger``); python-can's own ``python -m
can.logger`` records too. This adds what it lacks for this protocol: lowerbase's default
transport, a filter by catalog message name (``--only``), a decoded echo (``--print``) and an
end after ``--duration`` seconds. On a terminal, a status line shows the frame count as it
grows (rewritten in place, at most twice a second); when stderr is not a terminal, or with
``--print``, only the start and end lines are printed. ``--duration`` counts from the moment
the bus opens (frames queue for the file from then), not from when the writer is ready.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from lowerbase.cli.args import positive_seconds
from lowerbase.files import output_file


class LiveCount:
    """``recording: N frame(s), R/s -> FILE`` on a terminal, rewritten in place at most every
    ``period`` [s] of ``clock``; silent when ``stream`` is not a terminal."""

    def __init__(self, stream: TextIO, path: Path, *, enabled: bool = True, period: float = 0.5,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.stream, self.path, self.period, self.clock = stream, path, period, clock
        self.enabled = enabled and stream.isatty()
        self._t0 = clock()
        self._last = -float("inf")
        self._shown = False

    def update(self, count: int) -> None:
        if not self.enabled:
            return
        now = self.clock()
        if now - self._last < self.period:
            return
        self._last = now
        rate = count / (now - self._t0) if now > self._t0 else 0.0
        self.stream.write(f"\rrecording: {count} frame(s), {rate:.0f}/s -> {self.path}\x1b[K")
        self.stream.flush()
        self._shown = True

    def done(self) -> None:
        """Erase the status line (the caller prints the final count)."""
        if self._shown:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self._shown = False


class McapFrames:
    """``can.Logger``'s two methods over an MCAP file: /can/frames and /can/decoded/<Message>
    at the frames' own timestamps (docs/recording.md). No driver runs here, so no /odom."""

    def __init__(self, path: Path) -> None:
        from lowerbase.recording.mcap_writer import McapRecorder

        self.recorder = McapRecorder(path)

    def on_message_received(self, msg: Any) -> None:
        if msg.is_error_frame or msg.is_remote_frame:
            return
        self.recorder(float(msg.timestamp), "rx" if msg.is_rx else "tx",
                      int(msg.arbitration_id), bytes(msg.data))

    def stop(self) -> None:
        self.recorder.close()


#: at most this many frames already queued are written once --duration is over
DRAIN_LIMIT = 100_000


def drain(bus: Any, write: Callable[[Any], int]) -> int:
    """Write the frames ``bus`` received before now (queued while the loop was held up: the
    writer's set-up, a busy host); a frame received after now ends it. Returns the count."""
    cutoff, count = time.time(), 0
    for _ in range(DRAIN_LIMIT):
        msg = bus.recv(0.0)
        if msg is None or msg.timestamp > cutoff:
            break
        count += write(msg)
    return count


def open_writer(path: Path) -> Any:
    """The writer of ``path``: its suffix picks the format (.mcap: :class:`McapFrames`)."""
    import can

    return McapFrames(path) if path.suffix.lower() == ".mcap" else can.Logger(str(path))


def add_subparser(subparsers: Any) -> None:
    from lowerbase.transport import add_bus_arguments

    p = subparsers.add_parser(
        "record",
        help="record a live bus to .log (candump), .asc, .blf, .csv, .trc or .mcap",
        description="Record every frame on a bus (default: lowerbase's udp_multicast) with "
        "python-can's writers; the suffix picks the format. Stop with Ctrl-C or --duration.",
    )
    p.add_argument("file", help="output file: .log, .asc, .blf, .csv, .trc, or .mcap (raw "
                   "frames and decoded signals for Foxglove; docs/recording.md)")
    add_bus_arguments(p)
    p.add_argument("--duration", type=positive_seconds, metavar="S", help="stop after S seconds")
    p.add_argument("--only", action="append", metavar="NAME",
                   help="record only these catalog messages (repeatable), e.g. --only "
                   "WheelFeedback")
    p.add_argument("--print", dest="print_frames", action="store_true",
                   help="also print each recorded frame, decoded")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import can

    from lowerbase.errors import ConfigError, LowerbaseError
    from lowerbase.protocol.codec import default_codec
    from lowerbase.scenarios.replay import check_recording_path
    from lowerbase.transport import config_from_args, describe, open_bus

    mcap = Path(args.file).suffix.lower() == ".mcap"
    path = Path(args.file) if mcap else check_recording_path(args.file)
    output_file(path)
    codec = default_codec()
    ids: set[int] | None = None
    if args.only:
        ids = set()
        for name in args.only:
            try:
                ids.add(codec.message(name).frame_id)
            except LowerbaseError:
                raise ConfigError(f"--only {name}: not a message of the catalog; "
                                  f"known: {', '.join(m.name for m in codec)}") from None
    config = config_from_args(args)
    if mcap:  # its imports take seconds on a loaded host: before the bus opens, not after
        importlib.import_module("lowerbase.recording.mcap_writer")
    bus = open_bus(config)
    # frames queue for the file from here (those that arrive while the writer is set up are
    # written too): --duration counts from this moment, so the file spans it, any format
    started = time.monotonic()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    count = 0
    try:
        writer = open_writer(path)
    except (OSError, ValueError, LowerbaseError) as exc:
        bus.shutdown()
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"cannot write {path}: {exc}") from None
    print(f"lowerbase record: {describe(config)} -> {path}; Ctrl-C stops", file=sys.stderr)
    end = started + args.duration if args.duration is not None else None
    live = LiveCount(sys.stderr, path, enabled=not args.print_frames)

    def write(msg: Any) -> int:
        if ids is not None and msg.arbitration_id not in ids:
            return 0
        writer.on_message_received(msg)
        if args.print_frames:
            try:
                name, values = codec.decode(msg.arbitration_id, bytes(msg.data),
                                            decode_choices=True, strict=False)
            except LowerbaseError as exc:
                name, values = f"0x{msg.arbitration_id:03X}", {"error": str(exc)}
            print(f"{msg.timestamp:.6f} {name:<18} {values}", flush=True)
        return 1

    try:
        with contextlib.suppress(KeyboardInterrupt):
            while not stop.is_set():
                live.update(count)
                timeout = 0.2 if end is None else min(0.2, end - time.monotonic())
                if timeout <= 0:  # the duration is over: what queued before it goes in too
                    count += drain(bus, write)
                    break
                msg = bus.recv(timeout)
                if msg is not None:
                    count += write(msg)
    finally:
        live.done()
        writer.stop()
        with contextlib.suppress(can.CanError):
            bus.shutdown()
    print(f"lowerbase record: {count} frame(s) written to {path}", file=sys.stderr)
    return 0
