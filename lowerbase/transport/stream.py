"""Byte streams under the serial transports: a serial port (pyserial) or a pseudo-terminal.

``open_stream("pty:/tmp/lowerbase-tty")`` creates a pseudo-terminal, puts it in raw mode and
publishes its slave at the stable symlink; the other side opens that path like any serial port.
Anything else is handed to pyserial (``/dev/ttyUSB0``, ``COM3``, ``loop://``, ``socket://...``).
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import tty
from pathlib import Path
from typing import Protocol

from lowerbase.errors import TransportError

PTY_PREFIX = "pty"


class ByteStream(Protocol):
    """A bidirectional byte stream."""

    #: the path the peer opens (the pty slave or its symlink), or the port name
    name: str
    #: bytes that could not be written because nobody drained the other end
    dropped_bytes: int

    def read(self, timeout: float | None) -> bytes:
        """Whatever is available within ``timeout`` [s] (b"" when nothing)."""
        ...

    def write(self, data: bytes) -> None: ...

    def close(self) -> None: ...

    def fileno(self) -> int: ...


class PtyStream:
    """The master side of a new pseudo-terminal, optionally published at a symlink."""

    def __init__(self, link: str | Path | None = None) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line discipline: a clean 8-bit channel
        os.set_blocking(self._master, False)
        self.slave_name = os.ttyname(self._slave)
        self.link = Path(link) if link else None
        self.dropped_bytes = 0
        if self.link is not None:
            tmp = self.link.with_name(f".{self.link.name}.{os.getpid()}.tmp")
            try:
                with contextlib.suppress(FileNotFoundError):
                    tmp.unlink()
                tmp.symlink_to(self.slave_name)
                os.replace(tmp, self.link)  # atomic: a reader never sees a missing link
            except OSError as exc:
                self.close()
                raise TransportError(
                    f"cannot publish the pseudo-terminal at {link}: {exc}"
                ) from None
        self.name = str(self.link or self.slave_name)

    def fileno(self) -> int:
        return self._master

    def read(self, timeout: float | None) -> bytes:
        ready, _, _ = select.select([self._master], [], [], timeout)
        if not ready:
            return b""
        try:
            return os.read(self._master, 4096)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:  # the peer closed the slave: no data, not an error
                return b""
            raise

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                # nobody reads the other end and its buffer is full: a UART drops bytes too
                self.dropped_bytes += len(view)
                return
            view = view[n:]

    def close(self) -> None:
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)
        if self.link is not None:
            with contextlib.suppress(OSError):
                if self.link.is_symlink() and os.readlink(self.link) == self.slave_name:
                    self.link.unlink()


class SerialPortStream:
    """A serial port through pyserial (a device path or any pyserial URL)."""

    def __init__(self, port: str, baudrate: int = 115200) -> None:
        import serial

        try:
            self._port = serial.serial_for_url(port, baudrate=baudrate, timeout=0)
        except (serial.SerialException, ValueError) as exc:
            raise TransportError(f"cannot open serial port {port}: {exc}") from None
        self.name = port
        self.dropped_bytes = 0

    def fileno(self) -> int:
        return int(self._port.fileno())

    def read(self, timeout: float | None) -> bytes:
        import serial

        try:
            waiting = self._port.in_waiting
            if waiting:
                return bytes(self._port.read(waiting))
            self._port.timeout = timeout
            first = bytes(self._port.read(1))
            self._port.timeout = 0
            if first:
                return first + bytes(self._port.read(self._port.in_waiting))
            return b""
        except serial.SerialException as exc:
            raise TransportError(f"serial port {self.name}: {exc}") from None

    def write(self, data: bytes) -> None:
        import serial

        try:
            self._port.write(data)
        except serial.SerialException as exc:
            raise TransportError(f"serial port {self.name}: {exc}") from None

    def close(self) -> None:
        self._port.close()


def open_stream(spec: str, baudrate: int = 115200) -> ByteStream:
    """``pty`` / ``pty:LINK`` creates a pseudo-terminal; anything else opens a serial port."""
    if spec == PTY_PREFIX:
        return PtyStream()
    if spec.startswith(PTY_PREFIX + ":"):
        return PtyStream(spec[len(PTY_PREFIX) + 1 :])
    return SerialPortStream(spec, baudrate)
