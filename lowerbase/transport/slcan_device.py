"""The adapter side of the slcan (Lawicel ASCII) protocol, as a python-can bus.

The emulator opens ``SlcanDeviceBus("pty:/tmp/lowerbase-slcan")`` and looks, to the upper side,
like a USB-CAN adapter with the chassis behind it: the upper side opens the path with
python-can's own ``slcan`` interface (``--interface slcan --channel /tmp/lowerbase-slcan``).
Frames the host transmits (``tIIILDD..``) arrive here as received messages; frames sent here
reach the host as ``tIIILDD..\\r`` lines. Setup commands (``S6``, ``O``, ``C``, ``V``...) are
acknowledged with CR as an adapter does; unknown commands get BEL.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from typing import Any

import can

from lowerbase.transport.stream import ByteStream, open_stream

log = logging.getLogger(__name__)

_OK = b"\r"
_ERROR = b"\a"
_MAX_LINE = 64


class SlcanDeviceBus(can.BusABC):
    """A virtual slcan adapter on a serial port or pseudo-terminal."""

    def __init__(self, channel: str, stream: ByteStream | None = None, **kwargs: Any) -> None:
        self._stream = stream if stream is not None else open_stream(str(channel))
        self.channel_info = f"slcan device on {self._stream.name}"
        self._line = bytearray()
        self._pending: deque[can.Message] = deque()
        self.is_open = False  # the host's "O" opens the channel, "C" closes it
        self.bad_lines = 0
        super().__init__(channel=channel, **kwargs)

    @property
    def stream(self) -> ByteStream:
        return self._stream

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.is_fd or msg.is_remote_frame:
            raise can.CanOperationError("the slcan device carries classic data frames")
        if msg.is_extended_id:
            head = f"T{msg.arbitration_id:08X}{msg.dlc:d}"
        else:
            head = f"t{msg.arbitration_id:03X}{msg.dlc:d}"
        self._stream.write(head.encode() + bytes(msg.data).hex().upper().encode() + _OK)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self._pending:
            chunk = self._stream.read(timeout)
            for byte in chunk:
                if byte == 0x0D:
                    self._handle(bytes(self._line))
                    self._line.clear()
                elif len(self._line) < _MAX_LINE:
                    self._line.append(byte)
                else:  # an endless line is garbage: drop it, count it
                    self.bad_lines += 1
                    self._line.clear()
        if self._pending:
            return self._pending.popleft(), False
        return None, False

    def _handle(self, line: bytes) -> None:
        if not line:
            self._stream.write(_OK)
            return
        cmd = line[:1]
        if cmd in (b"t", b"T"):
            msg = self._parse_frame(line)
            if msg is None:
                self.bad_lines += 1
                self._stream.write(_ERROR)
                return
            self._pending.append(msg)
            self._stream.write(b"z\r" if cmd == b"t" else b"Z\r")
        elif cmd in (b"O", b"L"):
            self.is_open = True
            self._stream.write(_OK)
        elif cmd == b"C":
            self.is_open = False
            self._stream.write(_OK)
        elif cmd in (b"S", b"s", b"Z", b"M", b"m", b"F"):
            self._stream.write(_OK)
        elif cmd == b"V":
            self._stream.write(b"V1013\r")
        elif cmd == b"N":
            self._stream.write(b"NLB01\r")
        else:
            self.bad_lines += 1
            self._stream.write(_ERROR)

    def _parse_frame(self, line: bytes) -> can.Message | None:
        extended = line[:1] == b"T"
        id_len = 8 if extended else 3
        try:
            arbitration_id = int(line[1 : 1 + id_len], 16)
            dlc = int(line[1 + id_len : 2 + id_len], 16)
            data = bytes.fromhex(line[2 + id_len : 2 + id_len + 2 * dlc].decode("ascii"))
        except ValueError:
            return None
        if dlc > 8 or len(data) != dlc or len(line) != 2 + id_len + 2 * dlc:
            return None
        if arbitration_id > (0x1FFFFFFF if extended else 0x7FF):
            return None
        return can.Message(
            arbitration_id=arbitration_id, data=data, is_extended_id=extended,
            channel=self.channel_info, timestamp=time.time(),
        )

    def shutdown(self) -> None:
        super().shutdown()
        self._stream.close()
