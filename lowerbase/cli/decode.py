"""``lowerbase decode``: decode candump lines from stdin, or a python-can log file.

The reading is :mod:`lowerbase.transport.logfiles` (shared with ``lowerbase driver --replay``): a
text line that is not a frame is reported with file:line and skipped; a corrupt or truncated
file is reported with the frame it stopped after, and the exit code is 1.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TextIO

from lowerbase.errors import ConfigError, ProtocolError
from lowerbase.transport.logfiles import (  # noqa: F401 (re-exported: the decode API)
    MAX_REPORTED_LINES,
    BadLine,
    Corrupt,
    Frame,
    Item,
    frames_from_log,
    frames_from_text,
    parse_candump_line,
    parse_line,
)

_frames_from_text = frames_from_text
_frames_from_log = frames_from_log


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "decode",
        help="decode candump lines (stdin) or a python-can log file",
        description="Decode frames with the catalog. Reads candump output (default or -L "
        "format) or python-can's printer output (python -m can.logger) from stdin, or a log "
        "file in any format python-can reads (.log, .txt, .asc, .blf, .csv, .trc, ...). Values "
        "are shown at their signal's resolution. Unknown IDs, malformed frames and lines that "
        "are not frames are reported, not fatal; a corrupt file ends with exit code 1.",
    )
    p.add_argument("file", nargs="?", help="a python-can log file (default: stdin)")
    p.add_argument("--raw", action="store_true", help="show numbers instead of value names")
    p.add_argument("--only", metavar="NAME", action="append", help="show only these messages")
    p.set_defaults(func=run)


def _decimals(x: float) -> int:
    """Decimal places needed to show multiples of ``x`` exactly (0.001 -> 3, 0.25 -> 2)."""
    for d in range(10):
        scaled = abs(x) * 10**d
        if abs(scaled - round(scaled)) < 1e-6:
            return d
    return 9


def format_value(sig: Any, value: Any) -> str:
    """A decoded value at its signal's resolution (a choice name as it is)."""
    if isinstance(value, str):
        return value
    if sig.is_float:
        return f"{value:.7g}" if sig.length == 32 else repr(float(value))
    places = max(_decimals(sig.scale), _decimals(sig.offset))
    return str(round(value)) if places == 0 else f"{value:.{places}f}"


def format_signals(values: dict[str, Any], codec_msg: Any, *, raw: bool = False) -> str:
    from lowerbase.protocol.status_codes import describe

    parts = []
    for s in codec_msg.signals:
        if s.name not in values:  # multiplexed: another multiplexer value's signal
            continue
        v = values[s.name]
        text = format_value(s, v)
        if codec_msg.name == "StatusCode" and s.name == "Code" and not raw:
            text = f"0x{int(v):X}[{','.join(describe(int(v)))}]"
        unit = f" {s.unit}" if s.unit and not isinstance(v, str) else ""
        parts.append(f"{s.name}={text}{unit}")
    return " ".join(parts)


def decode_stream(frames: Iterable[Item], *, raw: bool, only: set[str] | None, out: TextIO,
                  err: TextIO | None = None) -> dict[str, int]:
    from lowerbase.protocol.codec import default_codec

    codec = default_codec()
    counts = {"frames": 0, "decoded": 0, "unknown_id": 0, "not_catalog": 0, "malformed": 0,
              "unparsed_lines": 0, "corrupt": 0}
    for item in frames:
        if isinstance(item, BadLine):
            counts["unparsed_lines"] += 1
            if err is not None and counts["unparsed_lines"] <= MAX_REPORTED_LINES:
                more = " (further ones are only counted)" \
                    if counts["unparsed_lines"] == MAX_REPORTED_LINES else ""
                print(f"# {item.where}: not a frame, skipped: {item.text[:80]!r}{more}",
                      file=err)
            continue
        if isinstance(item, Corrupt):
            counts["corrupt"] += 1
            if err is not None:
                print(f"lowerbase decode: error: {item.where}: corrupt file: {item.reason}",
                      file=err)
            continue
        counts["frames"] += 1
        stamp = f"({item.timestamp:.6f}) " if item.timestamp is not None else ""
        data, frame_id = item.data, item.frame_id
        if item.kind:
            counts["not_catalog"] += 1
            print(f"{stamp}0x{frame_id:03X} {item.kind} frame, not in the catalog "
                  f"[{len(data)}] {data.hex(' ')}", file=out)
            continue
        if frame_id not in codec:
            counts["unknown_id"] += 1
            print(f"{stamp}0x{frame_id:03X} unknown ID [{len(data)}] {data.hex(' ')}", file=out)
            continue
        msg = codec.message(frame_id)
        if only and msg.name not in only:
            continue
        try:
            values = msg.decode(data, decode_choices=not raw)
        except ProtocolError as exc:
            counts["malformed"] += 1
            print(f"{stamp}0x{frame_id:03X} {msg.name} malformed: {exc}", file=out)
            continue
        counts["decoded"] += 1
        print(f"{stamp}0x{frame_id:03X} {msg.name:<18} {format_signals(values, msg, raw=raw)}",
              file=out)
    return counts


def run(args: argparse.Namespace) -> int:
    if args.file:
        path = Path(args.file)
        if not path.is_file():
            raise ConfigError(f"no such file: {path}")
        frames: Iterable[Item] = _frames_from_log(path)
    else:
        frames = _frames_from_text(sys.stdin)
    counts = decode_stream(frames, raw=args.raw, only=set(args.only) if args.only else None,
                           out=sys.stdout, err=sys.stderr)
    summary = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items() if v)
    print(f"# {summary or 'no frames'}", file=sys.stderr)
    return 1 if counts["corrupt"] else 0
