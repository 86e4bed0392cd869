"""Reading CAN log files: candump text, python-can's .log/.txt, and python-can's binary readers.

Shared by ``lowerbase decode`` and ``lowerbase driver --replay``. Text input is read line by
line in three formats: candump's default and ``-L`` (= python-can's ``.log``), and python-can's
own printer (``python -m can.logger``, ``.txt``); a line that is none of them (also one that is
not valid UTF-8) becomes a :class:`BadLine` with file:line, and reading goes on. Other formats
(``.asc``, ``.blf``, ``.csv``, ``.trc``, ...) go through python-can's readers; a corrupt file,
or a .blf shorter than its header says (truncated), ends with a :class:`Corrupt` item naming the
frame it stopped after.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple, TextIO, TypeAlias

from lowerbase.errors import ConfigError

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


def frames_from_text(stream: TextIO, name: str = "<stdin>") -> Iterator[Item]:
    for number, line in enumerate(stream, 1):
        line = line.rstrip("\r\n")
        if not line.strip():
            continue
        try:
            frame = parse_line(line)
        except ValueError:
            frame = None
        yield frame if frame is not None else BadLine(f"{name}:{number}", line)


def frames_from_log(path: Path) -> Iterator[Item]:
    """The items of a log file; ConfigError when it cannot be opened at all."""
    if path.suffix.lower() in (".log", ".txt"):
        try:
            with path.open(encoding="utf-8", errors="replace") as stream:
                yield from frames_from_text(stream, str(path))
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
