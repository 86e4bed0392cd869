"""``lowerbase record``: record a live bus to a file other tools open (candump, ASC, BLF).

A thin layer over python-can's writers (``can.Logger``); python-can's own ``python -m
can.logger`` records too. This adds what it lacks for this protocol: lowerbase's default
transport, a filter by catalog message name (``--only``), a decoded echo (``--print``) and an
end after ``--duration`` seconds.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import time
from typing import Any

from lowerbase.cli.args import positive_seconds


def add_subparser(subparsers: Any) -> None:
    from lowerbase.transport import add_bus_arguments

    p = subparsers.add_parser(
        "record",
        help="record a live bus to .log (candump), .asc, .blf, .csv or .trc",
        description="Record every frame on a bus (default: lowerbase's udp_multicast) with "
        "python-can's writers; the suffix picks the format. Stop with Ctrl-C or --duration.",
    )
    p.add_argument("file", help="output file: .log, .asc, .blf, .csv or .trc")
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

    from lowerbase.bench.recording import check_recording_path
    from lowerbase.errors import ConfigError, LowerbaseError
    from lowerbase.protocol.codec import default_codec
    from lowerbase.transport import config_from_args, describe, open_bus

    path = check_recording_path(args.file)
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
    bus = open_bus(config)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    count = 0
    try:
        writer = can.Logger(str(path))
    except (OSError, ValueError) as exc:
        bus.shutdown()
        raise ConfigError(f"cannot write {path}: {exc}") from None
    print(f"lowerbase record: {describe(config)} -> {path}; Ctrl-C stops", file=sys.stderr)
    end = time.monotonic() + args.duration if args.duration is not None else None
    try:
        with contextlib.suppress(KeyboardInterrupt):
            while not stop.is_set():
                timeout = 0.2 if end is None else min(0.2, end - time.monotonic())
                if timeout <= 0:
                    break
                msg = bus.recv(timeout)
                if msg is None or (ids is not None and msg.arbitration_id not in ids):
                    continue
                writer.on_message_received(msg)
                count += 1
                if args.print_frames:
                    try:
                        name, values = codec.decode(msg.arbitration_id, bytes(msg.data),
                                                    decode_choices=True, strict=False)
                    except LowerbaseError as exc:
                        name, values = f"0x{msg.arbitration_id:03X}", {"error": str(exc)}
                    print(f"{msg.timestamp:.6f} {name:<18} {values}", flush=True)
    finally:
        writer.stop()
        with contextlib.suppress(can.CanError):
            bus.shutdown()
    print(f"lowerbase record: {count} frame(s) written to {path}", file=sys.stderr)
    return 0
