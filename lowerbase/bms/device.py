"""The BMS as a Modbus device: the pack model behind a lock, served by pymodbus 3.16.1.

:class:`BmsDevice` is the device without networking: it steps the pack, builds the register
images of :mod:`lowerbase.bms.registers` and validates threshold writes. :class:`BmsServer`
serves it over Modbus TCP and/or Modbus RTU (a serial port or a pseudo-terminal) with
pymodbus' own server classes: a :class:`pymodbus.simulator.SimDevice` whose documented
``action`` hook fills the registers from the model on every read and vets every write, and the
``trace_pdu`` hook that keeps the device silent to other unit ids, as a slave on an RS-485 line
must be.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import threading
from collections.abc import Sequence
from typing import Any

from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.registers import (
    HOLDING_BASE,
    HOLDING_COUNT,
    ILLEGAL_FUNCTION,
    INPUT_BASE,
    INPUT_COUNT,
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


def _check_tcp(host: str, port: int) -> None:
    """Fail early with the OS's reason; pymodbus only logs it."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise ModbusDeviceError(f"cannot listen on {host}:{port}: {exc.strerror}") from None
    family, kind, proto, _, addr = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(addr)
        except OSError as exc:
            raise ModbusDeviceError(
                f"cannot listen on Modbus TCP {host}:{port}: {exc.strerror or exc}"
            ) from None


def _check_serial(port: str) -> None:
    import serial

    try:
        serial.serial_for_url(port, exclusive=True).close()
    except (serial.SerialException, OSError, ValueError) as exc:
        raise ModbusDeviceError(f"cannot open serial port {port}: {exc}") from None


class BmsServer:
    """Serve a :class:`BmsDevice` over Modbus TCP and/or RTU from a background thread.

    ``tcp`` is (host, port) or None; port 0 picks a free port (see :attr:`tcp_address`).
    ``rtu`` is a serial device path (or a pyserial URL) or None. With a ``clock``, an update
    thread steps the device every ``update_period`` [s] of that clock (times ``speed``);
    without one the caller steps the device (tests on simulated time).
    """

    def __init__(
        self, device: BmsDevice, *, tcp: tuple[str, int] | None = DEFAULT_TCP,
        rtu: str | None = None, baudrate: int = DEFAULT_BAUDRATE, clock: Clock | None = None,
        update_period: float = 0.1, speed: float = 1.0,
    ) -> None:
        if tcp is None and rtu is None:
            raise ConfigError("the BMS needs at least one of Modbus TCP and Modbus RTU")
        self.device = device
        self.tcp = tcp
        self.rtu = rtu
        self.baudrate = baudrate
        self.clock = clock
        self.update_period = update_period
        self.speed = speed
        self.tcp_address: tuple[str, int] | None = None
        self._thread: threading.Thread | None = None
        self._updater: threading.Thread | None = None
        self._update_stop = threading.Event()
        self._ready = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._start_error: BaseException | None = None

    # -- pymodbus hooks -------------------------------------------------------------------

    async def _action(
        self, function_code: int, start_address: int, address: int, count: int,
        registers: list[int], set_values: list[int] | list[bool] | None,
    ) -> Any:
        """SimDevice action: refresh the block from the model, vet writes (see pymodbus'
        ``SimDevice.action``). Returns a pymodbus ``ExcCodes`` member to refuse."""
        from pymodbus.constants import ExcCodes

        if function_code in (1, 2, 5, 15):  # no coils or discrete inputs on this device
            return ExcCodes(ILLEGAL_FUNCTION)
        if set_values is not None and function_code in (6, 16, 23):
            try:
                self.device.write_holding(address, [int(v) for v in set_values])
            except RegisterValueError as exc:
                log.info("refused write at %#06x: %s", address, exc)
                return ExcCodes(exc.exception_code)
            return None
        if function_code == 4:
            image, base = self.device.input_registers(), INPUT_BASE
        else:
            image, base = self.device.holding_registers(), HOLDING_BASE
        offset = base - start_address
        registers[offset : offset + len(image)] = image
        return None

    def _trace_pdu(self, sending: bool, pdu: Any) -> Any:
        """Drop requests for other unit ids (a slave stays silent); broadcasts (0) pass."""
        if not sending and pdu.dev_id not in (self.device.unit, 0):
            return None
        return pdu

    def _sim_device(self) -> Any:
        from pymodbus.pdu.device import ModbusDeviceIdentification
        from pymodbus.simulator import DataType, SimData, SimDevice

        identity = ModbusDeviceIdentification(
            info_name={"VendorName": "lowerbase", "ProductCode": "BMS",
                       "ProductName": "emulated battery management system"}
        )
        placeholder = [SimData(0, values=False, datatype=DataType.BITS)]
        return SimDevice(
            self.device.unit,
            simdata=(
                placeholder,  # coils: refused by the action
                [SimData(0, values=False, datatype=DataType.BITS)],  # discrete inputs: refused
                [SimData(HOLDING_BASE, count=HOLDING_COUNT, values=0,
                         datatype=DataType.REGISTERS)],
                [SimData(INPUT_BASE, count=INPUT_COUNT, values=0,
                         datatype=DataType.REGISTERS, readonly=True)],
            ),
            identity=identity,
            action=self._action,
        )

    # -- lifecycle ------------------------------------------------------------------------

    async def _serve(self) -> None:
        from pymodbus import FramerType
        from pymodbus.server import ModbusSerialServer, ModbusTcpServer

        self._stopping = asyncio.Event()
        servers: list[Any] = []
        try:
            if self.tcp is not None:
                tcp_server = ModbusTcpServer(
                    self._sim_device(), address=self.tcp, trace_pdu=self._trace_pdu
                )
                servers.append(tcp_server)
                await tcp_server.serve_forever(background=True)
                sock = tcp_server.transport.sockets[0]  # type: ignore[attr-defined]
                self.tcp_address = (self.tcp[0], int(sock.getsockname()[1]))
            if self.rtu is not None:
                rtu_server = ModbusSerialServer(
                    self._sim_device(), framer=FramerType.RTU, port=self.rtu,
                    baudrate=self.baudrate, broadcast_enable=True, trace_pdu=self._trace_pdu,
                    reconnect_delay=0.5,
                )
                servers.append(rtu_server)
                await rtu_server.serve_forever(background=True)
        except Exception as exc:  # reported by start() in the caller's thread
            self._start_error = exc
        self._ready.set()
        if self._start_error is None:
            await self._stopping.wait()
        for server in servers:
            with contextlib.suppress(Exception):
                await server.shutdown()

    def _thread_main(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._serve())
        finally:
            pending = asyncio.all_tasks(loop)
            for task in pending:
                task.cancel()
            if pending:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            loop.close()
            self._ready.set()

    def start(self, timeout: float = 5.0) -> None:
        """Open the ports and serve; :class:`ModbusDeviceError` with the reason if one fails."""
        if self._thread is not None:
            raise ModbusDeviceError("the BMS server is already running")
        if self.tcp is not None:
            _check_tcp(*self.tcp)
        if self.rtu is not None:
            _check_serial(self.rtu)
        self._ready.clear()
        self._start_error = None
        self._thread = threading.Thread(target=self._thread_main, name="bms-modbus", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            self.stop()
            raise ModbusDeviceError("the Modbus server did not start in time")
        if self._start_error is not None:
            error = self._start_error
            self.stop()
            where = " and ".join(
                ([f"TCP {self.tcp[0]}:{self.tcp[1]}"] if self.tcp else [])
                + ([f"RTU {self.rtu}"] if self.rtu else [])
            )
            raise ModbusDeviceError(f"cannot serve Modbus {where}: {error}") from None
        if self.clock is not None:
            self._update_stop.clear()
            self._updater = threading.Thread(
                target=self.device.run, name="bms-update", daemon=True,
                args=(self.clock, self._update_stop),
                kwargs={"period": self.update_period, "speed": self.speed},
            )
            self._updater.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop serving and updating; idempotent. Ports are closed when this returns."""
        self._update_stop.set()
        if self._updater is not None:
            self._updater.join(timeout)
            self._updater = None
        if self._thread is not None:
            loop, stopping = self._loop, self._stopping
            if loop is not None and stopping is not None and not loop.is_closed():
                with contextlib.suppress(RuntimeError):
                    loop.call_soon_threadsafe(stopping.set)
            self._thread.join(timeout)
            if self._thread.is_alive():
                raise ModbusDeviceError("the Modbus server thread did not stop in time")
            self._thread = None
            self._loop = None
            self._stopping = None

    def __enter__(self) -> BmsServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
