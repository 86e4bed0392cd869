"""``lowerbase decode``: decode candump lines from stdin, or a python-can log file."""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, TextIO

from lowerbase.errors import ConfigError, ProtocolError

# candump -L / .log:  (1700000000.123456) vcan0 020#F401...
_LOG_LINE = re.compile(
    r"^\s*(?:\((?P<ts>[\d.]+)\)\s+)?(?P<ch>\S+)\s+(?P<id>[0-9A-Fa-f]{1,8})#(?P<data>[0-9A-Fa-f]*)\s*$"
)
# candump default:  vcan0  020   [6]  F4 01 06 FF 31 00
_CANDUMP_LINE = re.compile(
    r"^\s*(?:\(\s*(?P<ts>[\d.]+)\)\s+)?(?P<ch>\S+)\s+(?P<id>[0-9A-Fa-f]{3,8})\s+\[(?P<dlc>\d)\]\s*(?P<data>(?:[0-9A-Fa-f]{2}\s*)*)$"
)


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "decode",
        help="decode candump lines (stdin) or a python-can log file",
        description="Decode frames with the catalog. Reads candump output (default or -L "
        "format) from stdin, or a log file in any format python-can reads (.log, .asc, .blf, "
        ".csv, .trc, ...). Unknown IDs and malformed frames are reported, not fatal.",
    )
    p.add_argument("file", nargs="?", help="a python-can log file (default: stdin)")
    p.add_argument("--raw", action="store_true", help="show numbers instead of value names")
    p.add_argument("--only", metavar="NAME", action="append", help="show only these messages")
    p.set_defaults(func=run)


def parse_candump_line(line: str) -> tuple[float | None, int, bytes] | None:
    """(timestamp, ID, payload) of one candump line, or None for a line that is not a frame."""
    m = _LOG_LINE.match(line) or _CANDUMP_LINE.match(line)
    if not m:
        return None
    ts = float(m["ts"]) if m["ts"] else None
    data = bytes.fromhex(re.sub(r"\s+", "", m["data"]))
    return ts, int(m["id"], 16), data


def _frames_from_text(stream: TextIO) -> Iterator[tuple[float | None, int, bytes] | str]:
    for line in stream:
        line = line.rstrip("\n")
        if not line.strip():
            continue
        try:
            parsed = parse_candump_line(line)
        except ValueError:
            parsed = None
        yield parsed if parsed is not None else line


def _frames_from_log(path: Path) -> Iterator[tuple[float | None, int, bytes] | str]:
    import can

    try:
        reader = can.LogReader(str(path))
    except (ValueError, OSError) as exc:
        raise ConfigError(f"cannot read {path}: {exc}") from None
    for msg in reader:
        yield msg.timestamp, msg.arbitration_id, bytes(msg.data)


def format_signals(values: dict[str, Any], codec_msg: Any) -> str:
    parts = []
    for s in codec_msg.signals:
        if s.name not in values:  # multiplexed: another multiplexer value's signal
            continue
        v = values[s.name]
        text = f"{v:.6g}" if isinstance(v, float) else str(v)
        unit = f" {s.unit}" if s.unit and not isinstance(v, str) else ""
        parts.append(f"{s.name}={text}{unit}")
    return " ".join(parts)


def decode_stream(
    frames: Iterable[tuple[float | None, int, bytes] | str], *, raw: bool, only: set[str] | None,
    out: TextIO,
) -> dict[str, int]:
    from lowerbase.protocol.codec import default_codec

    codec = default_codec()
    counts = {"frames": 0, "decoded": 0, "unknown_id": 0, "malformed": 0, "unparsed_lines": 0}
    for item in frames:
        if isinstance(item, str):
            counts["unparsed_lines"] += 1
            continue
        ts, frame_id, data = item
        counts["frames"] += 1
        stamp = f"({ts:.6f}) " if ts is not None else ""
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
        print(f"{stamp}0x{frame_id:03X} {msg.name:<18} {format_signals(values, msg)}", file=out)
    return counts


def run(args: argparse.Namespace) -> int:
    if args.file:
        path = Path(args.file)
        if not path.exists():
            raise ConfigError(f"no such file: {path}")
        frames: Iterable[Any] = _frames_from_log(path)
    else:
        frames = _frames_from_text(sys.stdin)
    counts = decode_stream(frames, raw=args.raw, only=set(args.only) if args.only else None,
                           out=sys.stdout)
    summary = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items() if v)
    print(f"# {summary or 'no frames'}", file=sys.stderr)
    return 0
