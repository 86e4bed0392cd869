"""The catalog's frames over a byte stream (UART): framer and streaming deframer.

Frame layout (all multi-byte fields little-endian, like the CAN payloads)::

    offset  size  field
    0       2     SOF      0xAA 0x55
    2       1     LEN      payload length, 0..8 (classic CAN)
    3       2     ID       11-bit CAN identifier (upper 5 bits zero)
    5       LEN   PAYLOAD  the CAN payload, exactly as on the bus
    5+LEN   1     SEQ      link sequence counter, +1 per frame sent (mod 256)
    6+LEN   2     CRC      CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over LEN..SEQ

A frame is LEN + 8 bytes long. The deframer resynchronises on the next SOF after garbage,
a truncated frame or a bad CRC, and counts each kind of error; it never raises on input and
its buffer is bounded.
"""

from __future__ import annotations

import binascii
from dataclasses import asdict, dataclass

from lowerbase.errors import FramingError

SOF = b"\xaa\x55"
HEADER_SIZE = 5  # SOF + LEN + ID
OVERHEAD = 8  # SOF(2) + LEN(1) + ID(2) + SEQ(1) + CRC(2)
MAX_PAYLOAD = 8
MAX_ID = 0x7FF


def crc16(data: bytes | bytearray | memoryview, init: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (check value 0x29B1 for b"123456789")."""
    return binascii.crc_hqx(data, init)


@dataclass(frozen=True)
class SerialFrame:
    """One deframed frame: the CAN ID, payload and link sequence number."""

    frame_id: int
    data: bytes
    seq: int


class Framer:
    """Builds serial frames with a rolling link sequence counter."""

    def __init__(self) -> None:
        self.seq = 0

    def encode(self, frame_id: int, data: bytes | bytearray) -> bytes:
        if not 0 <= frame_id <= MAX_ID:
            raise FramingError(f"frame ID {frame_id:#x} is not an 11-bit identifier")
        if len(data) > MAX_PAYLOAD:
            raise FramingError(f"payload of {len(data)} bytes; at most {MAX_PAYLOAD}")
        body = bytes((len(data), frame_id & 0xFF, frame_id >> 8)) + bytes(data) + bytes(
            (self.seq,)
        )
        self.seq = (self.seq + 1) & 0xFF
        return SOF + body + crc16(body).to_bytes(2, "little")


@dataclass
class DeframerStats:
    """Counts of what the deframer saw; every byte is accounted for in one of them."""

    frames: int = 0
    garbage_bytes: int = 0  #: bytes outside any frame, skipped while hunting for SOF
    bad_crc: int = 0  #: complete frames whose CRC did not match
    bad_length: int = 0  #: LEN above MAX_PAYLOAD or a reserved ID bit set
    truncated: int = 0  #: frames cut short by the start of the next frame or by a flush
    seq_gaps: int = 0  #: frames lost according to the sequence counter

    @property
    def total_errors(self) -> int:
        return self.bad_crc + self.bad_length + self.truncated

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class Deframer:
    """Streaming deframer: ``feed`` bytes in any chunking, get whole frames out."""

    def __init__(self) -> None:
        # holds at most one incomplete frame (< OVERHEAD + MAX_PAYLOAD bytes) between feeds
        self._buf = bytearray()
        self._expected_seq: int | None = None
        self.stats = DeframerStats()

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[SerialFrame]:
        buf = self._buf
        buf += chunk
        out: list[SerialFrame] = []
        stats = self.stats
        while True:
            start = buf.find(SOF)
            if start < 0:
                # keep a trailing 0xAA: it may be the first half of the next SOF
                keep = 1 if buf[-1:] == SOF[:1] else 0
                stats.garbage_bytes += len(buf) - keep
                del buf[: len(buf) - keep]
                break
            if start:
                stats.garbage_bytes += start
                del buf[:start]
            if len(buf) < HEADER_SIZE:
                break
            length = buf[2]
            if length > MAX_PAYLOAD or buf[4] & 0xF8:
                stats.bad_length += 1
                del buf[:2]  # skip this SOF, hunt for the next
                continue
            total = OVERHEAD + length
            if len(buf) < total:
                # wait for the rest, unless a new frame already started inside this one
                inner = buf.find(SOF, 2)
                if inner > 0 and len(buf) - inner >= HEADER_SIZE and self._plausible(inner):
                    stats.truncated += 1
                    del buf[:inner]
                    continue
                break
            crc = buf[total - 2] | (buf[total - 1] << 8)
            if crc16(memoryview(buf)[2 : total - 2]) != crc:
                inner = buf.find(SOF, 2, total)
                if inner > 0:
                    stats.truncated += 1
                    del buf[:inner]
                else:
                    stats.bad_crc += 1
                    del buf[:2]
                continue
            frame_id = buf[3] | (buf[4] << 8)
            seq = buf[total - 3]
            out.append(SerialFrame(frame_id, bytes(buf[5 : 5 + length]), seq))
            stats.frames += 1
            if self._expected_seq is not None and seq != self._expected_seq:
                stats.seq_gaps += (seq - self._expected_seq) & 0xFF
            self._expected_seq = (seq + 1) & 0xFF
            del buf[:total]
        return out

    def _plausible(self, pos: int) -> bool:
        """Whether a SOF at ``pos`` starts a header that could be a frame."""
        return self._buf[pos + 2] <= MAX_PAYLOAD and not self._buf[pos + 4] & 0xF8

    def flush(self) -> None:
        """Drop a partial frame left at the end of the stream (e.g. after an idle timeout)."""
        if len(self._buf) >= 2 and self._buf[:2] == SOF:
            self.stats.truncated += 1
        elif self._buf:
            self.stats.garbage_bytes += len(self._buf)
        self._buf.clear()

    @property
    def pending(self) -> int:
        """Bytes held while waiting for the rest of a frame."""
        return len(self._buf)
