"""python-can's udp_multicast, hardened: only datagrams sent to the group are frames.

python-can binds its socket to ``0.0.0.0:PORT``, so a plain unicast datagram that any host
sends to that port is taken as a frame. :class:`GroupOnlyMulticastBus` binds the socket to
the group address itself (the kernel then delivers only datagrams whose destination is the
group). With hop limit 0 (lowerbase's default, "this host only") it also joins the group and
sends on the loopback interface only and sets ``IP_MULTICAST_ALL`` off, so multicast that
arrives from the network is not delivered either. ``open_bus`` uses it for every
``udp_multicast`` configuration; the wire format is python-can's, so its tools interoperate.
"""

from __future__ import annotations

import socket
import struct
from typing import Any

import can
from can.interfaces.udp_multicast.bus import GeneralPurposeUdpMulticastBus, UdpMulticastBus

_IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)  # Linux


class _GroupSocket(GeneralPurposeUdpMulticastBus):
    def _create_socket(self, address_family: socket.AddressFamily) -> socket.socket:
        if address_family != socket.AF_INET:  # IPv6 groups: python-can's own socket
            return super()._create_socket(address_family)
        local = self.hop_limit == 0
        iface = socket.inet_aton("127.0.0.1" if local else "0.0.0.0")
        sock = socket.socket(address_family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL,
                            struct.pack("@I", self.hop_limit))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if hasattr(socket, "SO_REUSEPORT"):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            sock.bind((self.group, self.port))  # the group's datagrams only, never unicast
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                            socket.inet_aton(self.group) + iface)
            if local:
                sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, iface)
                sock.setsockopt(socket.IPPROTO_IP, _IP_MULTICAST_ALL, 0)
        except OSError as error:
            sock.close()
            raise can.CanInitializationError(
                f"could not bind {self.group}:{self.port}: {error}") from error
        self.timestamp_nanosecond = False
        return sock


class GroupOnlyMulticastBus(UdpMulticastBus):
    """``udp_multicast`` that accepts only what arrives on its group (see the module)."""

    def __init__(self, channel: str = UdpMulticastBus.DEFAULT_GROUP_IPv4, port: int = 43113,
                 hop_limit: int = 0, **kwargs: Any) -> None:
        super().__init__(channel, port, hop_limit, **kwargs)
        self._multicast.shutdown()
        self._multicast = _GroupSocket(channel, port, hop_limit)
