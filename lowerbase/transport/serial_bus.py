"""A python-can bus that carries the catalog's frames over a serial byte stream.

Registered with python-can as interface ``lowerbase_serial``, so every python-can tool and
``can.Bus(interface="lowerbase_serial", channel="/dev/ttyUSB0")`` speak the serial framing of
:mod:`lowerbase.protocol.framing`. ``channel="pty:/tmp/lowerbase-tty"`` creates a
pseudo-terminal and publishes it at that path (the emulator side).
"""

from __future__ import annotations

import logging
import time
from collections import deque
from typing import Any

import can

from lowerbase.protocol.framing import Deframer, Framer
from lowerbase.transport.stream import ByteStream, open_stream

log = logging.getLogger(__name__)


class SerialFrameBus(can.BusABC):
    """CAN frames inside CRC-protected serial frames."""

    def __init__(
        self, channel: str, baudrate: int = 115200, stream: ByteStream | None = None,
        **kwargs: Any,
    ) -> None:
        self._stream = stream if stream is not None else open_stream(str(channel), baudrate)
        self.channel_info = f"serial framing on {self._stream.name}"
        self._framer = Framer()
        self.deframer = Deframer()
        self._pending: deque[can.Message] = deque()
        super().__init__(channel=channel, **kwargs)

    @property
    def stream(self) -> ByteStream:
        return self._stream

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.is_extended_id or msg.is_remote_frame or msg.is_fd:
            raise can.CanOperationError("the serial framing carries classic 11-bit data frames")
        self._stream.write(self._framer.encode(msg.arbitration_id, bytes(msg.data)))

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self._pending:
            chunk = self._stream.read(timeout)
            if chunk:
                for frame in self.deframer.feed(chunk):
                    self._pending.append(
                        can.Message(
                            arbitration_id=frame.frame_id,
                            data=frame.data,
                            is_extended_id=False,
                            channel=self.channel_info,
                            timestamp=time.time(),  # reception time, as python-can backends do
                        )
                    )
        if self._pending:
            return self._pending.popleft(), False
        return None, False

    def shutdown(self) -> None:
        super().shutdown()
        self._stream.close()
