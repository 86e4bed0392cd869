"""How the emulated lower computer reads its BMS: a :class:`BmsLink` with ``poll()``.

Every implementation goes through the same register encoding (:func:`encode_snapshot` /
:func:`decode_snapshot`), so a value read in-process is bit for bit the value a Modbus master
reads. ``poll()`` returns None when the link is silent (timeout, refused connection, exception
response); the reason is kept in ``last_error``.
"""

from __future__ import annotations

import logging
from typing import Any, Protocol, runtime_checkable

from lowerbase.bms.registers import INPUT_BASE, INPUT_COUNT, decode_snapshot, encode_snapshot
from lowerbase.bms.snapshot import BmsSnapshot

log = logging.getLogger(__name__)

#: default response timeout of the Modbus links [s]
DEFAULT_TIMEOUT = 0.25


@runtime_checkable
class BmsLink(Protocol):
    """A BMS poller."""

    def poll(self) -> BmsSnapshot | None:
        """Read the BMS once; None when it does not answer."""
        ...

    def close(self) -> None:
        """Release the link's port or socket."""
        ...


class SnapshotSource(Protocol):
    """Anything that reads out a BMS snapshot (a BatteryPack or a BmsDevice)."""

    def snapshot(self) -> BmsSnapshot: ...


class InProcessBmsLink:
    """Reads the model directly, through the input-register encoding.

    Set ``silent`` to emulate a dead link (poll returns None).
    """

    def __init__(self, source: SnapshotSource) -> None:
        self.source = source
        self.silent = False
        self.last_error: str | None = None

    def poll(self) -> BmsSnapshot | None:
        if self.silent:
            self.last_error = "link silenced"
            return None
        return decode_snapshot(encode_snapshot(self.source.snapshot()))

    def close(self) -> None:
        """Nothing to release."""


class _ModbusBmsLink:
    """Common part of the Modbus pollers (pymodbus sync clients, one retry-free request)."""

    def __init__(self, client: Any, unit: int) -> None:
        self._client = client
        self.unit = unit
        self.last_error: str | None = None

    def poll(self) -> BmsSnapshot | None:
        from pymodbus.exceptions import ModbusException

        try:
            if not self._client.connected and not self._client.connect():
                self.last_error = "cannot connect"
                return None
            response = self._client.read_input_registers(
                INPUT_BASE, count=INPUT_COUNT, device_id=self.unit
            )
        except (ModbusException, OSError) as exc:
            self.last_error = str(exc)
            self._client.close()
            return None
        if response.isError():
            self.last_error = f"exception response {getattr(response, 'exception_code', '?')}"
            return None
        if len(response.registers) != INPUT_COUNT:
            self.last_error = f"{len(response.registers)} registers instead of {INPUT_COUNT}"
            return None
        self.last_error = None
        return decode_snapshot(response.registers)

    def read_holding(self, address: int, count: int) -> list[int] | None:
        """Read threshold registers (None when silent or refused)."""
        from pymodbus.exceptions import ModbusException

        try:
            if not self._client.connected and not self._client.connect():
                return None
            response = self._client.read_holding_registers(
                address, count=count, device_id=self.unit
            )
        except (ModbusException, OSError) as exc:
            self.last_error = str(exc)
            return None
        return None if response.isError() else list(response.registers)

    def close(self) -> None:
        self._client.close()

    def __enter__(self) -> _ModbusBmsLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ModbusTcpBmsLink(_ModbusBmsLink):
    """Polls a BMS over Modbus TCP (pymodbus ``ModbusTcpClient``)."""

    def __init__(
        self, host: str = "127.0.0.1", port: int = 5020, *, unit: int = 1,
        timeout: float = DEFAULT_TIMEOUT,
    ) -> None:
        from pymodbus.client import ModbusTcpClient

        super().__init__(
            ModbusTcpClient(host, port=port, timeout=timeout, retries=0, reconnect_delay=0),
            unit,
        )


class ModbusRtuBmsLink(_ModbusBmsLink):
    """Polls a BMS over Modbus RTU on a serial port (pymodbus ``ModbusSerialClient``)."""

    def __init__(
        self, port: str, *, unit: int = 1, baudrate: int = 19200,
        timeout: float = DEFAULT_TIMEOUT,
    ) -> None:
        from pymodbus import FramerType
        from pymodbus.client import ModbusSerialClient

        super().__init__(
            ModbusSerialClient(
                port, framer=FramerType.RTU, baudrate=baudrate, timeout=timeout, retries=0,
                reconnect_delay=0,
            ),
            unit,
        )
