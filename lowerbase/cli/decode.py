"""``lowerbase decode``: decode candump lines from stdin, or a python-can log file.

Text input (stdin, ``.log``, ``.txt``) is read line by line in three formats: candump's default
and ``-L`` (= python-can's ``.log``), and python-can's own printer (``python -m can.logger``,
``.txt``); a line that is none of them is reported with file:line and skipped. Other formats
(``.asc``, ``.blf``, ``.csv``, ``.trc``, ...) go through python-can's readers; a corrupt or
truncated file is reported with the frame it stopped after, and the exit code is 1.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, NamedTuple, TextIO, TypeAlias

from lowerbase.errors import ConfigError, ProtocolError

# candump -L / .log:  (1700000000.123456) vcan0 020#F401...   (also 020#R, 020##1F401...;
# python-can's .log writer adds the direction, R or T)
_LOG_LINE = re.compile(
    r"^\s*(?:\((?P<ts>[\d.]+)\)\s+)?(?P<ch>\S+)\s+(?P<id>[0-9A-Fa-f]{1,8})"
    r"#(?P<fd>#[0-9A-Fa-f])?(?P<data>[0-9A-Fa-f]*|R\d*)(?:\s+[RT])?\s*$"
)
_CAN_ERR_FLAG = 0x20000000
# candump default:  vcan0  020   [6]  F4 01 06 FF 31 00
_CANDUMP_LINE = re.compile(
    r"^\s*(?:\(\s*(?P<ts>[\d.]+)\)\s+)?(?P<ch>\S+)\s+(?P<id>[0-9A-Fa-f]{3,8})\s+\[(?P<dlc>\d)\]\s*(?P<data>(?:[0-9A-Fa-f]{2}\s*)*)$"
)
# python-can's printer (can.Message.__str__, `python -m can.logger`, can.Logger("x.txt")):
# Timestamp: 1700000000.123456    ID:      020    S Rx                DL:  6    f4 01 ...
_PRINTER_LINE = re.compile(
    r"^\s*Timestamp:\s*(?P<ts>[\d.]+)\s+ID:\s*(?P<id>[0-9A-Fa-f]{1,8})\s+(?P<ext>[SX])\s+"
    r"(?:Rx|Tx)(?P<flags>[ ERFBSI]*?)\s*DL:\s*(?P<dlc>\d+)(?P<rest>.*)$"
)
_HEX_BYTES = re.compile(r"\s*((?:[0-9A-Fa-f]{2}(?:\s+|$))*)")
#: text lines not reported one by one after this many (they are all counted)
MAX_REPORTED_LINES = 10


class Frame(NamedTuple):
    timestamp: float | None
    frame_id: int
    data: bytes
    #: why this cannot be a catalog frame ("extended", "remote", "FD", "error"), "" if it can
    kind: str = ""


class BadLine(NamedTuple):
    where: str  #: file:line
    text: str


class Corrupt(NamedTuple):
    where: str
    reason: str


Item: TypeAlias = Frame | BadLine | Corrupt


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


def parse_line(line: str) -> Frame | None:
    """The frame of one text line (candump, candump -L, python-can printer), else None."""
    m = _LOG_LINE.match(line)
    if m:
        kind = "FD" if m["fd"] else "remote" if m["data"].startswith("R") else ""
        data = b"" if kind == "remote" else bytes.fromhex(m["data"])
        return _frame(m["ts"], m["id"], data, kind)
    m = _CANDUMP_LINE.match(line)
    if m:
        return _frame(m["ts"], m["id"], bytes.fromhex(re.sub(r"\s+", "", m["data"])), "")
    m = _PRINTER_LINE.match(line)
    if m:
        flags = m["flags"].split()
        kind = ("error" if "E" in flags else "remote" if "R" in flags
                else "FD" if "F" in flags else "extended" if m["ext"] == "X" else "")
        hexes = _HEX_BYTES.match(m["rest"])
        data = bytes.fromhex(re.sub(r"\s+", "", hexes[1] if hexes else ""))
        if kind != "remote" and len(data) != int(m["dlc"]):
            return None
        return Frame(float(m["ts"]), int(m["id"], 16), data, kind)
    return None


def _frame(ts: str | None, frame_id: str, data: bytes, kind: str) -> Frame:
    # candump prints standard IDs with 3 digits, extended ones with 8
    number = int(frame_id, 16)
    if not kind and len(frame_id) > 3:
        kind = "error" if number & _CAN_ERR_FLAG else "extended"
    return Frame(float(ts) if ts else None, number, data, kind)


def parse_candump_line(line: str) -> tuple[float | None, int, bytes] | None:
    """(timestamp, ID, payload) of one candump line, or None for a line that is not a frame."""
    frame = parse_line(line)
    return None if frame is None else (frame.timestamp, frame.frame_id, frame.data)


def _frames_from_text(stream: TextIO, name: str = "<stdin>") -> Iterator[Item]:
    for number, line in enumerate(stream, 1):
        line = line.rstrip("\r\n")
        if not line.strip():
            continue
        try:
            frame = parse_line(line)
        except ValueError:
            frame = None
        yield frame if frame is not None else BadLine(f"{name}:{number}", line)


def _frames_from_log(path: Path) -> Iterator[Item]:
    if path.suffix.lower() in (".log", ".txt"):
        try:
            with path.open(encoding="utf-8", errors="replace") as stream:
                yield from _frames_from_text(stream, str(path))
        except OSError as exc:
            raise ConfigError(f"cannot read {path}: {exc}") from None
        return
    import can

    try:
        reader = can.LogReader(str(path))
    except Exception as exc:  # any reader error: a file python-can cannot open
        raise ConfigError(f"cannot read {path}: {exc or type(exc).__name__}") from None
    count = 0
    try:
        for msg in reader:
            count += 1
            kind = ("error" if msg.is_error_frame else "remote" if msg.is_remote_frame
                    else "FD" if msg.is_fd else "extended" if msg.is_extended_id else "")
            yield Frame(msg.timestamp, msg.arbitration_id, bytes(msg.data), kind)
    except Exception as exc:  # python-can's readers raise anything on a corrupt file
        yield Corrupt(f"{path}: after frame {count}", str(exc) or type(exc).__name__)
        return
    declared = getattr(reader, "file_size", None)  # BLF: the size the header promises
    if isinstance(declared, int) and declared > path.stat().st_size:
        yield Corrupt(f"{path}: after frame {count}",
                      f"truncated ({path.stat().st_size} of {declared} bytes)")


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
