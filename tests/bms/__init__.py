"""Tests of lowerbase.bms: pack physics, protections, registers, Modbus device, frames, CLI."""

from __future__ import annotations

import socket

from lowerbase.transport import free_loopback_port


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    return free_loopback_port(socket.SOCK_STREAM)
