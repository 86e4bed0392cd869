"""The BMS's Modbus slave: one PDU handler behind Modbus TCP (MBAP) and Modbus RTU framing.

:func:`handle_pdu` answers one request PDU from a :class:`RegisterDevice` (a
:class:`~lowerbase.bms.device.BmsDevice`) following the Modbus application protocol v1.1b3:
a function code the device does not offer gets ILLEGAL FUNCTION (01), a malformed request
(wrong length, quantity 0 or too large, byte count mismatch) ILLEGAL DATA VALUE (03), an
address outside the tables ILLEGAL DATA ADDRESS (02), an unexpected failure SERVER DEVICE
FAILURE (04); every exception response is ``function code | 0x80, code``. Nothing in an
answer names the software behind it (no FC 0x11 / 0x2B identification).

:func:`serve_tcp_connection` answers every complete MBAP request of a stream in order (also
several in one segment, or one split over several) and closes an idle connection;
:class:`RtuFramer` cuts RTU frames out of a byte stream by length and CRC, and by the silence
between frames.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Protocol

from lowerbase.bms.registers import (
    DEVICE_FAILURE,
    HOLDING_BASE,
    HOLDING_COUNT,
    ILLEGAL_DATA_ADDRESS,
    ILLEGAL_DATA_VALUE,
    ILLEGAL_FUNCTION,
    INPUT_BASE,
    INPUT_COUNT,
    RegisterValueError,
)

log = logging.getLogger(__name__)

READ_HOLDING, READ_INPUT, WRITE_SINGLE, WRITE_MULTIPLE, READ_WRITE = 0x03, 0x04, 0x06, 0x10, 0x17
#: largest quantities of the standard: read 125 registers, write 123, write 121 in FC 23
MAX_READ, MAX_WRITE, MAX_RW_WRITE = 125, 123, 121
WRITE_CODES = frozenset({WRITE_SINGLE, WRITE_MULTIPLE, READ_WRITE})


class RegisterDevice(Protocol):
    """What the handler needs of the device (see :class:`~lowerbase.bms.device.BmsDevice`)."""

    unit: int

    def input_registers(self) -> list[int]: ...

    def holding_registers(self) -> list[int]: ...

    def write_holding(self, address: int, values: Sequence[int]) -> None: ...


class _Refused(Exception):
    def __init__(self, code: int) -> None:
        self.code = code


def _u16(data: bytes, offset: int) -> int:
    return int.from_bytes(data[offset : offset + 2], "big")


def _read(device: RegisterDevice, table: int, address: int, count: int) -> bytes:
    if not 1 <= count <= MAX_READ:
        raise _Refused(ILLEGAL_DATA_VALUE)
    if table == READ_INPUT:
        base, size, image = INPUT_BASE, INPUT_COUNT, device.input_registers
    else:
        base, size, image = HOLDING_BASE, HOLDING_COUNT, device.holding_registers
    offset = address - base
    if offset < 0 or offset + count > size:
        raise _Refused(ILLEGAL_DATA_ADDRESS)
    words = image()[offset : offset + count]
    return bytes([2 * count]) + b"".join(w.to_bytes(2, "big") for w in words)


#: each kind of drop (and refused writes) is logged the first LOG_FIRST times, then every
#: LOG_EVERY-th with the count so far: a port scan or a broken client does not flood the log
LOG_FIRST, LOG_EVERY = 5, 100
_refused_writes: Counter[str] = Counter()  #: process-wide, by exception code


def count_suffix(n: int) -> str | None:
    """What the n-th occurrence of a kind of event adds to its log line, or None when it is not
    logged (the first :data:`LOG_FIRST`, then every :data:`LOG_EVERY`-th)."""
    if n > LOG_FIRST and n % LOG_EVERY:
        return None
    return "" if n < LOG_FIRST else f" ({n} so far; further ones are logged every {LOG_EVERY}th)"


def _write(device: RegisterDevice, address: int, data: bytes) -> None:
    values = [_u16(data, i) for i in range(0, len(data), 2)]
    try:
        device.write_holding(address, values)
    except RegisterValueError as exc:
        key = f"{exc.exception_code:02x}"
        _refused_writes[key] += 1
        more = count_suffix(_refused_writes[key])
        if more is not None:
            log.info("refused write at %#06x: %s%s", address, exc, more)
        raise _Refused(exc.exception_code) from None


def _check_write(count: int, byte_count: int, limit: int, data: bytes) -> None:
    if not 1 <= count <= limit or byte_count != 2 * count or len(data) != byte_count:
        raise _Refused(ILLEGAL_DATA_VALUE)


def _execute(device: RegisterDevice, pdu: bytes) -> bytes:
    """The response PDU body (after the function code); raises _Refused."""
    fc = pdu[0]
    if fc in (READ_HOLDING, READ_INPUT, WRITE_SINGLE):
        if len(pdu) != 5:
            raise _Refused(ILLEGAL_DATA_VALUE)
        address, value = _u16(pdu, 1), _u16(pdu, 3)
        if fc == WRITE_SINGLE:
            _write(device, address, pdu[3:5])
            return pdu[1:5]
        return _read(device, fc, address, value)
    if fc == WRITE_MULTIPLE:
        if len(pdu) < 6:
            raise _Refused(ILLEGAL_DATA_VALUE)
        address, count = _u16(pdu, 1), _u16(pdu, 3)
        _check_write(count, pdu[5], MAX_WRITE, pdu[6:])
        _write(device, address, pdu[6:])
        return pdu[1:5]
    if fc == READ_WRITE:
        if len(pdu) < 10:
            raise _Refused(ILLEGAL_DATA_VALUE)
        read_address, read_count = _u16(pdu, 1), _u16(pdu, 3)
        write_address, write_count = _u16(pdu, 5), _u16(pdu, 7)
        if not 1 <= read_count <= MAX_READ:
            raise _Refused(ILLEGAL_DATA_VALUE)
        _check_write(write_count, pdu[9], MAX_RW_WRITE, pdu[10:])
        if not 0 <= read_address - HOLDING_BASE <= HOLDING_COUNT - read_count:
            raise _Refused(ILLEGAL_DATA_ADDRESS)
        _write(device, write_address, pdu[10:])  # the write happens before the read
        return _read(device, READ_HOLDING, read_address, read_count)
    raise _Refused(ILLEGAL_FUNCTION)  # incl. coils, diagnostics, 0x11 and 0x2B identification


def handle_pdu(device: RegisterDevice, pdu: bytes) -> bytes:
    """The response PDU to request ``pdu`` (function code first; must not be empty)."""
    fc = pdu[0]
    try:
        return bytes([fc]) + _execute(device, pdu)
    except _Refused as refused:
        code = refused.code
    except Exception:  # the model failed: the standard answer, and the details in the log
        log.exception("BMS device failure on request %s", pdu.hex(" "))
        code = DEVICE_FAILURE
    return bytes([fc | 0x80, code])


class SlaveCore:
    """Unit-id filtering and drop counting shared by the TCP and RTU framings.

    ``dropped`` counts what got no answer, by reason; drops are logged rate-limited per reason
    (:func:`count_suffix`: the first five, then every 100th with the count).
    """

    def __init__(self, device: RegisterDevice) -> None:
        self.device = device
        self.dropped: Counter[str] = Counter()

    def drop(self, reason: str, detail: str = "") -> None:
        self.dropped[reason] += 1
        more = count_suffix(self.dropped[reason])
        if more is not None:
            log.info("Modbus: dropped %s%s%s", reason, f" ({detail})" if detail else "", more)

    def answer(self, unit: int, pdu: bytes) -> bytes | None:
        """The response PDU, or None when the device stays silent (another unit id, a
        broadcast to unit 0, which is executed if it is a write, or an empty PDU)."""
        if not pdu:
            self.drop("empty PDU")
            return None
        if unit == 0:
            if pdu[0] in WRITE_CODES:
                handle_pdu(self.device, pdu)
            return None
        if unit != self.device.unit:
            self.dropped["other unit id"] += 1  # normal on a shared line: not logged
            return None
        if pdu[0] == 0 or pdu[0] & 0x80:  # 0 is invalid, 0x80-0xFF mark exception responses:
            self.drop("invalid function code", f"0x{pdu[0]:02X}")  # an answer would look
            return None  # like an exception frame itself
        return handle_pdu(self.device, pdu)


# -- Modbus TCP ------------------------------------------------------------------------------

MBAP_SIZE = 7
#: MBAP length field: unit id + function code + at most 252 data bytes (253-byte PDU)
MAX_MBAP_LENGTH = 254


async def serve_tcp_connection(
    core: SlaveCore, reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
    idle_timeout: float | None,
) -> None:
    """Answer the requests of one connection in order until it closes, idles for
    ``idle_timeout`` [s] (None: never) or breaks framing."""
    peer = writer.get_extra_info("peername")
    try:
        while True:
            header = await asyncio.wait_for(reader.readexactly(MBAP_SIZE), idle_timeout)
            tid, protocol, length, unit = header[0:2], _u16(header, 2), _u16(header, 4), header[6]
            if not 1 <= length <= MAX_MBAP_LENGTH:
                core.drop("connection with a bad MBAP length", f"{length} from {peer}")
                return
            pdu = await asyncio.wait_for(reader.readexactly(length - 1), idle_timeout)
            if protocol != 0:
                core.drop("frame with a protocol id other than 0", f"{protocol}")
                continue
            response = core.answer(unit, pdu)
            if response is not None:
                size = (len(response) + 1).to_bytes(2, "big")
                writer.write(tid + b"\0\0" + size + bytes([unit]) + response)
                # a client that stops reading its answers is as good as idle
                await asyncio.wait_for(writer.drain(), idle_timeout)
    except asyncio.IncompleteReadError:
        return
    except asyncio.TimeoutError:
        core.drop("idle connection", f"{peer}, {idle_timeout:g} s")
    except (ConnectionError, OSError):
        return
    except Exception as exc:  # never a traceback from a connection handler
        log.error("Modbus TCP connection %s closed: %s: %s", peer, type(exc).__name__, exc)
    finally:
        writer.close()
        with contextlib.suppress(Exception):
            await writer.wait_closed()


# -- Modbus RTU ------------------------------------------------------------------------------


def crc16(data: bytes) -> int:
    """Modbus RTU CRC (polynomial 0xA001, initial 0xFFFF); sent low byte first."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def with_crc(frame: bytes) -> bytes:
    return frame + crc16(frame).to_bytes(2, "little")


def _request_length(buf: bytes) -> int | None:
    """The length of the RTU request that starts ``buf`` when its function code fixes it."""
    if len(buf) < 2:
        return None
    fc = buf[1]
    if fc in (0x01, 0x02, 0x03, 0x04, 0x05, 0x06):
        return 8
    if fc in (0x0F, 0x10) and len(buf) >= 7:
        return 9 + buf[6]
    if fc == 0x17 and len(buf) >= 11:
        return 13 + buf[10]
    return None


def silence_s(baudrate: int) -> float:
    """The RTU inter-frame silence t3.5: 3.5 characters of 11 bits; 1.75 ms above 19200 Bd."""
    return 0.00175 if baudrate > 19200 else 3.5 * 11 / baudrate


class RtuFramer:
    """Cuts requests out of an RTU byte stream and answers them through ``core``.

    :meth:`feed` takes received bytes; a request whose function code fixes its length is
    answered as soon as it is complete with a good CRC. :meth:`silence` is called after the
    inter-frame silence: what is buffered then is one frame (answered if its CRC is good,
    e.g. an unknown function code or a malformed request) or noise (dropped and counted).
    """

    def __init__(self, core: SlaveCore, send: Callable[[bytes], None]) -> None:
        self.core = core
        self.send = send
        self.buffer = b""
        self._garbled = False

    def feed(self, data: bytes) -> None:
        self.buffer += data
        while not self._garbled and (length := _request_length(self.buffer)) is not None:
            if len(self.buffer) < length:
                return
            frame = self.buffer[:length]
            if crc16(frame[:-2]) != int.from_bytes(frame[-2:], "little"):
                self._garbled = True  # not a frame boundary we know: wait for silence
                return
            self.buffer = self.buffer[length:]
            self._answer(frame)
        if len(self.buffer) > 256:  # longer than any RTU frame: noise
            self._garbled = True

    def silence(self) -> None:
        buf, self.buffer, self._garbled = self.buffer, b"", False
        if not buf:
            return
        if len(buf) < 4 or crc16(buf[:-2]) != int.from_bytes(buf[-2:], "little"):
            self.core.drop("RTU noise or bad CRC", f"{len(buf)} bytes")
            return
        self._answer(buf)

    def _answer(self, frame: bytes) -> None:
        response = self.core.answer(frame[0], frame[1:-2])
        if response is not None:
            self.send(with_crc(bytes([frame[0]]) + response))
