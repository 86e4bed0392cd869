"""Transports: every link to a lower computer is a python-can bus.

CAN backends come from python-can by name (socketcan, virtual, udp_multicast, slcan, pcan, ...),
chosen with python-can's own flags, config file and environment variables. The serial framing
(``lowerbase_serial``) and the virtual slcan adapter (``slcan_device``) are python-can backends
too, registered through entry points, so the emulator, the driver and the benches never care
which one they run on.

With nothing configured, the default is ``udp_multicast`` with hop limit 0: datagrams never
leave this host, and two processes on any machine (no SocketCAN needed) share one bus.
"""

from __future__ import annotations

import argparse
import json
import logging
import socket
from typing import Any

import can

from lowerbase.errors import TransportError
from lowerbase.transport.config import (  # noqa: F401 (the package's interface)
    DEFAULT_CHANNEL,
    DEFAULT_HOP_LIMIT,
    DEFAULT_INTERFACE,
    DEFAULT_PORT,
    bus_config,
)

log = logging.getLogger(__name__)


def free_loopback_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port on 127.0.0.1 that nothing is bound to right now (UDP by default, or
    ``socket.SOCK_STREAM`` for TCP): for a bus, a Modbus server or a ROS master of a test,
    benchmark or demo that must not collide with another run."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def is_catalog_frame(msg: can.Message) -> bool:
    """Whether ``msg`` can be a catalog frame at all: a classic data frame with an 11-bit ID.

    Extended, remote, error and CAN FD frames never are; treating an extended ID 0x10 as the
    standard 0x10 would, for example, turn any device's frame into a ControlCommand.
    """
    return not (msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.is_fd)


def add_bus_arguments(parser: argparse.ArgumentParser, *, serial: bool = True) -> None:
    """python-can's bus flags (-i/-c/-b/--bus-kwargs...) plus ``--serial PORT``."""
    from can.cli import add_bus_arguments as can_add_bus_arguments

    can_add_bus_arguments(parser)
    from lowerbase.transport.options import use_strict_bus_kwargs

    use_strict_bus_kwargs(parser)  # a key given twice is refused, not silently replaced
    if serial:
        parser.add_argument(
            "--serial",
            metavar="PORT",
            help="use the serial framing instead of CAN: a serial device (/dev/ttyUSB0), "
            "a pyserial URL, or pty:LINK to create a pseudo-terminal published at LINK",
        )
        parser.add_argument(
            "--baudrate", type=int, default=115200, help="serial baud rate (default 115200)"
        )


def config_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The bus configuration named by parsed ``add_bus_arguments`` flags."""
    serial_port = getattr(args, "serial", None)
    if serial_port:
        return {
            "interface": "lowerbase_serial",
            "channel": serial_port,
            "baudrate": getattr(args, "baudrate", 115200),
        }
    extra: dict[str, Any] = {}
    for key in ("bitrate", "fd", "data_bitrate", "can_filters", "timing"):
        value = getattr(args, key, None)
        if value is not None:
            extra[key] = value
    from lowerbase.transport.options import checked_config  # --bus-kwargs checked, typed

    return checked_config(getattr(args, "interface", None), getattr(args, "channel", None),
                          extra, getattr(args, "bus_kwargs", None) or {})


def open_bus(config: dict[str, Any] | None = None, **kwargs: Any) -> can.BusABC:
    """Open a python-can bus; failures become one clear :class:`TransportError`."""
    cfg = bus_config(**{**(config or {}), **kwargs})
    try:
        if cfg.get("interface") == DEFAULT_INTERFACE:  # udp_multicast: the group's datagrams only
            from lowerbase.transport.multicast import GroupOnlyMulticastBus

            rest = {k: v for k, v in cfg.items() if k != "interface"}
            return GroupOnlyMulticastBus(**rest)
        return can.Bus(**cfg)
    except (can.CanError, OSError, ValueError, ImportError, TypeError) as exc:
        where = f"{cfg.get('interface')} channel {cfg.get('channel')!r}"
        reason = str(exc) or type(exc).__name__
        if exc.__cause__ is not None and str(exc.__cause__):
            reason = f"{reason}: {exc.__cause__}"
        hint = ""
        if cfg.get("interface") == "socketcan":
            hint = " (is the interface up? see vcan/README.md)"
        raise TransportError(f"cannot open {where}: {reason}{hint}") from None


def describe(config: dict[str, Any]) -> str:
    """A one-line description of a bus configuration, for 'listening on ...' messages."""
    rest = {k: v for k, v in config.items() if k not in ("interface", "channel")}
    extra = f" {json.dumps(rest, default=str)}" if rest else ""
    return f"{config.get('interface')} channel {config.get('channel')}{extra}"
