"""The BMS as a Modbus device: the pack model behind a lock, and the server that serves it.

:class:`BmsDevice` is the device without networking: it steps the pack, builds the register
images of :mod:`lowerbase.bms.registers` and validates threshold writes. :class:`BmsServer`
serves it over Modbus TCP and/or Modbus RTU (a serial port or a pseudo-terminal) through the
framing and request handling of :mod:`lowerbase.bms.modbus`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import select
import socket
import threading
from collections.abc import Sequence
from typing import Any

from lowerbase.bms.modbus import RtuFramer, SlaveCore, serve_tcp_connection, silence_s
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.registers import (
    RegisterValueError,
    apply_holding_write,
    encode_protection,
    encode_snapshot,
)
from lowerbase.bms.snapshot import BmsSnapshot
from lowerbase.bms.status import ChargeMode
from lowerbase.clock import Clock
from lowerbase.errors import ConfigError, ModbusDeviceError

log = logging.getLogger(__name__)

DEFAULT_TCP = ("127.0.0.1", 5020)
DEFAULT_UNIT = 1
DEFAULT_BAUDRATE = 19200
#: a Modbus TCP connection silent this long [s] is closed
DEFAULT_IDLE_TIMEOUT = 60.0


class BmsDevice:
    """The emulated BMS: a :class:`BatteryPack` plus its register images, thread-safe.

    ``load_current`` [A] is what the motors draw; :meth:`step` and the update loop of
    :meth:`run` use it unless a step is given its own.
    """

    def __init__(self, pack: BatteryPack | None = None, *, unit: int = DEFAULT_UNIT) -> None:
        if not 1 <= unit <= 247:
            raise ConfigError(f"Modbus unit id must be 1-247, got {unit}")
        self.pack = pack or BatteryPack()
        self.unit = unit
        self.load_current = 0.0
        self._lock = threading.Lock()

    def step(self, dt: float, load_current: float | None = None) -> None:
        """Advance the pack by ``dt`` [s] (simulated time)."""
        with self._lock:
            self.pack.step(dt, self.load_current if load_current is None else load_current)

    def connect_charger(self, mode: ChargeMode | int = ChargeMode.AUTO) -> None:
        with self._lock:
            self.pack.connect_charger(mode)

    def disconnect_charger(self) -> None:
        with self._lock:
            self.pack.disconnect_charger()

    def snapshot(self) -> BmsSnapshot:
        """The pack's reading at full precision."""
        with self._lock:
            return self.pack.snapshot()

    def input_registers(self) -> list[int]:
        """Input-register image, ``INPUT_COUNT`` words from ``INPUT_BASE``."""
        return encode_snapshot(self.snapshot())

    def holding_registers(self) -> list[int]:
        """Holding-register image, ``HOLDING_COUNT`` words from ``HOLDING_BASE``."""
        with self._lock:
            return encode_protection(self.pack.config.protection)

    def write_holding(self, address: int, values: Sequence[int]) -> None:
        """Write threshold registers; :class:`RegisterValueError` refuses and changes nothing."""
        with self._lock:
            current = encode_protection(self.pack.config.protection)
            _, protection = apply_holding_write(current, address, values)
            try:
                self.pack.set_protection(protection)
            except ConfigError as exc:  # a rule that ties thresholds to the pack config
                raise RegisterValueError(str(exc)) from None

    def run(
        self, clock: Clock, stop: threading.Event, *, period: float = 0.1, speed: float = 1.0
    ) -> None:
        """Update loop: every ``period`` [s] of ``clock`` time, step the pack by the elapsed
        time x ``speed``, until ``stop`` is set. On a :class:`~lowerbase.clock.SimClock` the
        loop runs as fast as the CPU allows."""
        if period <= 0 or speed <= 0:
            raise ConfigError("update period and speed must be > 0")
        last = clock.now()
        deadline = last
        while not stop.is_set():
            deadline += period
            clock.sleep_until(deadline)
            now = clock.now()
            self.step((now - last) * speed)
            last = now


def parse_host_port(text: str, default_port: int = DEFAULT_TCP[1]) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST``, ``:PORT`` or ``[v6]:PORT`` -> (host, port); ConfigError if bad."""
    host, sep, port_text = text.rpartition(":")
    if not sep or (text.startswith("[") and not host.endswith("]")):
        host, port_text = text, str(default_port)
    host = host.strip("[]") or DEFAULT_TCP[0]
    try:
        port = int(port_text)
    except ValueError:
        raise ConfigError(f"bad TCP address {text!r}: port {port_text!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise ConfigError(f"bad TCP address {text!r}: port must be 0-65535")
    return host, port


def _listen_tcp(host: str, port: int) -> socket.socket:
    """A listening socket, or :class:`ModbusDeviceError` with the OS's reason."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise ModbusDeviceError(f"cannot listen on {host}:{port}: {exc.strerror}") from None
    family, kind, proto, _, addr = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(addr)
        sock.listen(16)
    except OSError as exc:
        sock.close()
        raise ModbusDeviceError(
            f"cannot listen on Modbus TCP {host}:{port}: {exc.strerror or exc}"
        ) from None
    sock.setblocking(False)
    return sock


def _open_serial(port: str, baudrate: int) -> Any:
    import serial

    try:
        ser = serial.serial_for_url(port, baudrate=baudrate, timeout=0, exclusive=True)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise ModbusDeviceError(f"cannot open serial port {port}: {exc}") from None
    try:
        ser.fileno()
    except Exception:
        ser.close()
        raise ModbusDeviceError(f"cannot serve Modbus RTU on {port}: not a serial device") from None
    return ser


class BmsServer:
    """Serve a :class:`BmsDevice` over Modbus TCP and/or RTU from background threads.

    ``tcp`` is (host, port) or None; port 0 picks a free port (see :attr:`tcp_address`).
    A TCP connection that sends nothing for ``idle_timeout`` [s] is closed (None: never).
    ``rtu`` is a serial device path or None. With a ``clock``, an update thread steps the
    device every ``update_period`` [s] of that clock (times ``speed``); without one the
    caller steps the device (tests on simulated time). :attr:`dropped` counts the requests
    that got no answer, by reason (see :class:`~lowerbase.bms.modbus.SlaveCore`).
    """

    def __init__(
        self, device: BmsDevice, *, tcp: tuple[str, int] | None = DEFAULT_TCP,
        rtu: str | None = None, baudrate: int = DEFAULT_BAUDRATE, clock: Clock | None = None,
        update_period: float = 0.1, speed: float = 1.0,
        idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT,
    ) -> None:
        if tcp is None and rtu is None:
            raise ConfigError("the BMS needs at least one of Modbus TCP and Modbus RTU")
        if idle_timeout is not None and idle_timeout <= 0:
            raise ConfigError("the idle timeout must be > 0 s (or None: never)")
        self.device = device
        self.tcp = tcp
        self.rtu = rtu
        self.baudrate = baudrate
        self.clock = clock
        self.update_period = update_period
        self.speed = speed
        self.idle_timeout = idle_timeout
        self.tcp_address: tuple[str, int] | None = None
        self._core = SlaveCore(device)
        self.dropped = self._core.dropped
        self._threads: list[threading.Thread] = []
        self._stop = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None

    # -- Modbus TCP -----------------------------------------------------------------------

    def _tcp_main(self, sock: socket.socket, loop: asyncio.AbstractEventLoop,
                  stopping: asyncio.Event) -> None:
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._serve_tcp(sock, stopping))
        finally:
            sock.close()
            loop.close()

    async def _serve_tcp(self, sock: socket.socket, stopping: asyncio.Event) -> None:
        connections: set[asyncio.Task[Any]] = set()

        async def on_connect(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            task = asyncio.current_task()
            assert task is not None
            connections.add(task)
            try:
                await serve_tcp_connection(self._core, reader, writer, self.idle_timeout)
            finally:
                connections.discard(task)

        server = await asyncio.start_server(on_connect, sock=sock)
        await stopping.wait()
        server.close()
        for task in list(connections):
            task.cancel()
        await asyncio.gather(server.wait_closed(), *connections, return_exceptions=True)

    # -- Modbus RTU -----------------------------------------------------------------------

    def _rtu_main(self, ser: Any) -> None:
        framer = RtuFramer(self._core, ser.write)
        gap = silence_s(self.baudrate)
        try:
            while not self._stop.is_set():
                try:
                    wait = gap if framer.buffer else 0.1
                    ready, _, _ = select.select([ser.fileno()], [], [], wait)
                    data = os.read(ser.fileno(), 512) if ready else None
                    if data == b"":
                        raise OSError("the port reports data but has none (disconnected?)")
                    if data:
                        framer.feed(data)  # may answer: writes to the port
                    elif framer.buffer:
                        framer.silence()
                except OSError as exc:  # incl. serial.SerialException: unplugged, closed
                    log.warning("Modbus RTU on %s: %s; reopening", self.rtu, exc)
                    ser.close()
                    ser = self._reopen_serial()
                    if ser is None:
                        return
                    framer = RtuFramer(self._core, ser.write)
        finally:
            if ser is not None:
                ser.close()

    def _reopen_serial(self) -> Any:
        assert self.rtu is not None
        while not self._stop.wait(0.5):
            try:
                return _open_serial(self.rtu, self.baudrate)
            except ModbusDeviceError:
                continue
        return None

    # -- lifecycle ------------------------------------------------------------------------

    def start(self) -> None:
        """Open the ports and serve; :class:`ModbusDeviceError` with the reason if one fails."""
        if self._threads:
            raise ModbusDeviceError("the BMS server is already running")
        sock = _listen_tcp(*self.tcp) if self.tcp is not None else None
        try:
            ser = _open_serial(self.rtu, self.baudrate) if self.rtu is not None else None
        except ModbusDeviceError:
            if sock is not None:
                sock.close()
            raise
        self._stop.clear()
        if sock is not None:
            assert self.tcp is not None
            self.tcp_address = (self.tcp[0], int(sock.getsockname()[1]))
            self._loop, self._stopping = asyncio.new_event_loop(), asyncio.Event()
            self._threads.append(threading.Thread(
                target=self._tcp_main, args=(sock, self._loop, self._stopping),
                name="bms-modbus", daemon=True,
            ))
        if ser is not None:
            self._threads.append(threading.Thread(
                target=self._rtu_main, args=(ser,), name="bms-modbus-rtu", daemon=True
            ))
        if self.clock is not None:
            self._threads.append(threading.Thread(
                target=self.device.run, name="bms-update", daemon=True,
                args=(self.clock, self._stop),
                kwargs={"period": self.update_period, "speed": self.speed},
            ))
        for thread in self._threads:
            thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop serving and updating; idempotent. Ports are closed when this returns."""
        self._stop.set()
        loop, stopping, self._loop, self._stopping = self._loop, self._stopping, None, None
        if loop is not None and stopping is not None:
            with contextlib.suppress(RuntimeError):  # already closed
                loop.call_soon_threadsafe(stopping.set)
        threads, self._threads = self._threads, []
        for thread in threads:
            thread.join(timeout)
        if any(thread.is_alive() for thread in threads):
            raise ModbusDeviceError("the Modbus server threads did not stop in time")

    def __enter__(self) -> BmsServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
