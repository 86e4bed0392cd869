"""udp_multicast accepts only datagrams sent to its group; hop limit 0 stays on loopback."""

from __future__ import annotations

import socket
from typing import Any

import can
from can.interfaces.udp_multicast.utils import pack_message

from lowerbase.transport import open_bus


def _frame(frame_id: int) -> can.Message:
    return can.Message(arbitration_id=frame_id, data=b"\x01\x02", is_extended_id=False)


def test_unicast_datagrams_to_the_port_are_not_frames(udp_bus_config: dict[str, Any]) -> None:
    bus = open_bus(udp_bus_config)  # the only socket on the port: it gets whatever arrives
    group, port = udp_bus_config["channel"], udp_bus_config["port"]
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as intruder:
            intruder.sendto(pack_message(_frame(0x10)), ("127.0.0.1", port))
            intruder.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
            intruder.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                                socket.inet_aton("127.0.0.1"))
            intruder.sendto(pack_message(_frame(0x20)), (group, port))  # on the group: a frame
        got = []
        while (msg := bus.recv(1.0)) is not None:
            got.append(msg.arbitration_id)
            if msg.arbitration_id == 0x20:
                break
        assert got == [0x20]
    finally:
        bus.shutdown()


def test_hop_limit_zero_binds_the_group_on_loopback(udp_bus_config: dict[str, Any]) -> None:
    bus = open_bus(udp_bus_config)
    try:
        sock = bus._multicast._socket  # type: ignore[attr-defined]
        assert sock.getsockname() == (udp_bus_config["channel"], udp_bus_config["port"])
        assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0
        assert socket.inet_ntoa(sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                                                4)) == "127.0.0.1"
    finally:
        bus.shutdown()
