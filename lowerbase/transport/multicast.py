"""python-can's udp_multicast, hardened and lean: only the group's datagrams are frames.

python-can binds its socket to ``0.0.0.0:PORT``, so a plain unicast datagram that any host
sends to that port is taken as a frame. :class:`GroupOnlyMulticastBus` binds its receive
socket to the group address itself (the kernel then delivers only datagrams whose destination
is the group). With hop limit 0 (lowerbase's default, "this host only") it sends on the
loopback interface and takes only what this host sent:

- It joins the group on loopback and on the default multicast interface (the one the routing
  table picks for the group, where python-can's ``UdpMulticastBus``, ``can.player`` or any
  plain sender sends; the kernel loops a copy of such a send back to the host's members of
  the group on that interface), and on no other (``IP_MULTICAST_ALL`` off).
- Before it joins, a kernel socket filter is attached that drops every datagram that arrived
  on another interface than loopback and is not such a looped-back copy (``PACKET_LOOPBACK``,
  which only the kernel's multicast loop makes; multicast from the network is
  ``PACKET_MULTICAST``, see :func:`lowerbase.transport.udp_wire.socket_filter`). The verdict
  is the kernel's own record of where the packet came from, not an address a sender can
  forge, needs no list of this host's addresses (which change), and costs nothing per frame.
  Nothing from another host ever reaches the queue, not even before the first ``recv``.
- Where no socket filter can be attached it joins on loopback only (as before: python-can's
  default sender is then not heard, and a warning says so), never on the network.

Joining on the default interface announces the membership there (IGMP) as any multicast
member does; frames sent with hop limit (TTL) 0 never leave the host, ours or python-can's.
``LOWERBASE_MULTICAST_JOIN=loopback`` in the environment keeps the join on loopback alone (no
IGMP on the network; python-can's default sender is then not heard): the test suite sets it,
as its traffic must stay on loopback or the project's own virtual devices.

With hop limit 0 it sends from a socket of its own (``127.0.0.1``, an ephemeral port), and a
kernel socket filter on the receive socket drops the datagrams that came from it: like a CAN
controller (and SocketCAN's default), a bus does not receive its own frames, and they cost
nothing on the way back. ``can_filters`` are applied in the kernel too (a foreign ID never
wakes the process; see :func:`lowerbase.transport.udp_wire.socket_filter`) and again, exactly,
in user space. Sending and receiving skip python-can's per-frame dict (:mod:`udp_wire`) and
``send_frame(frame_id, data)`` sends a classic frame without building a ``can.Message``; the
bytes on the wire are python-can's, so its tools interoperate. ``open_bus`` uses this class for
every ``udp_multicast`` configuration.
"""

from __future__ import annotations

import ctypes
import errno
import logging
import os
import select
import socket
import struct
import time
from collections.abc import Callable
from typing import Any

import can
from can import CanProtocol
from can.interfaces.udp_multicast.bus import GeneralPurposeUdpMulticastBus, UdpMulticastBus
from can.interfaces.udp_multicast.utils import is_msgpack_installed
from can.typechecking import CanFilters

from lowerbase.transport import udp_wire

log = logging.getLogger(__name__)

#: ``loopback``: join the group on loopback only (see the module's docstring)
JOIN_ENV = "LOWERBASE_MULTICAST_JOIN"

_IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)  # Linux
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
_TIMESPEC = struct.Struct("@ll")
#: receive buffer asked for (the kernel caps it at net.core.rmem_max): a process that is
#: descheduled for a while keeps what arrived meanwhile
RECEIVE_BUFFER = 1 << 21


def _loopback_index() -> int:
    try:
        return socket.if_nametoindex("lo")
    except OSError:  # pragma: no cover - Linux names it lo; its index is 1 in every namespace
        return 1


def _attach(sock: socket.socket, prog: list[udp_wire.Insn]) -> bool:
    """Attach a classic-BPF program to ``sock`` (replacing the one before, atomically)."""
    raw = b"".join(struct.pack("HBBI", *insn) for insn in prog)
    buf = ctypes.create_string_buffer(raw, len(raw))
    fprog = struct.pack("HL", len(prog), ctypes.addressof(buf))
    try:
        sock.setsockopt(socket.SOL_SOCKET, _SO_ATTACH_FILTER, fprog)
    except OSError as error:
        log.debug("socket filter not attached: %s", error)
        return False
    return True


class _GroupSocket(GeneralPurposeUdpMulticastBus):
    #: loopback's index when the receive socket drops what other hosts send (hop limit 0)
    host_only: int | None = None

    def _create_socket(self, address_family: socket.AddressFamily) -> socket.socket:
        if address_family != socket.AF_INET:  # IPv6 groups: python-can's own socket
            return super()._create_socket(address_family)
        local = self.hop_limit == 0
        iface = socket.inet_aton("127.0.0.1" if local else "0.0.0.0")
        group = socket.inet_aton(self.group)
        sock = socket.socket(address_family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL,
                            struct.pack("@I", self.hop_limit))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if hasattr(socket, "SO_REUSEPORT"):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
            sock.bind((self.group, self.port))  # the group's datagrams only, never unicast
            if local:
                sock.setsockopt(socket.IPPROTO_IP, _IP_MULTICAST_ALL, 0)
                lo = _loopback_index()
                if _attach(sock, udp_wire.socket_filter(None, None, host_only=lo)):
                    self.host_only = lo
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, group + iface)
            if local:
                sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, iface)
                self._join_default(sock, group)
            try:
                sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self.timestamp_nanosecond = True
            except OSError:
                self.timestamp_nanosecond = False
        except OSError as error:
            sock.close()
            raise can.CanInitializationError(
                f"could not bind {self.group}:{self.port}: {error}") from error
        return sock

    def _join_default(self, sock: socket.socket, group: bytes) -> None:
        """Join on the default multicast interface too, behind the host-only filter."""
        join = os.environ.get(JOIN_ENV, "")
        if join == "loopback":
            return
        if join:
            log.warning("%s=%r is not a choice (loopback); joining as by default", JOIN_ENV, join)
        if self.host_only is None:
            log.warning("no socket filter on this system: udp_multicast %s:%d hears only "
                        "senders on loopback (python-can's default sender is not heard)",
                        self.group, self.port)
            return
        try:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                            group + socket.inet_aton("0.0.0.0"))
        except OSError as error:
            # EADDRINUSE: the default interface is loopback (joined); ENODEV: no multicast
            # route, so nobody can send on a default interface either
            if error.errno != errno.EADDRINUSE:
                log.debug("not joined on the default interface: %s", error)


def _sender(port: int) -> socket.socket:
    """A socket that sends to the group on loopback only, from a port of its own."""
    for _ in range(8):
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 0))
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            tx.bind(("127.0.0.1", 0))
        except OSError as error:
            tx.close()
            raise can.CanInitializationError(f"could not open a sending socket: {error}") \
                from error
        if tx.getsockname()[1] != port:  # the group's port is every plain sender's source
            return tx
        tx.close()
    raise can.CanInitializationError("no free loopback port to send from")


class GroupOnlyMulticastBus(UdpMulticastBus):
    """``udp_multicast`` that accepts only what arrives on its group (see the module)."""

    def __init__(self, channel: str = UdpMulticastBus.DEFAULT_GROUP_IPv4, port: int = 43113,
                 hop_limit: int = 0, receive_own_messages: bool = False, fd: bool = True,
                 **kwargs: Any) -> None:
        # UdpMulticastBus.__init__ without its socket (bound to 0.0.0.0:PORT, which a fleet's
        # port range can collide with)
        is_msgpack_installed()
        if receive_own_messages:
            raise can.CanInterfaceNotImplementedError(
                "receiving own messages is not yet implemented")
        self._kernel_masks: list[tuple[int, int]] | None = None
        self._accepts: dict[int, bool] = {}  #: classic 11-bit ID -> passes the filters
        self._rx: socket.socket | None = None
        self._multicast: _GroupSocket
        self._multicast = group = _GroupSocket(channel, port, hop_limit)
        self._can_protocol = CanProtocol.CAN_FD if fd else CanProtocol.CAN_20
        self._own_port: int | None = None
        self._tx = group._socket
        if group.ip_version == 4 and hop_limit == 0:
            try:
                self._tx = _sender(port)
            except BaseException:
                group.shutdown()
                raise
            self._own_port = int(self._tx.getsockname()[1])
        self._dest = (group.group, port)
        self._tx_timeout: float | None = None
        self._anc = socket.CMSG_SPACE(_TIMESPEC.size) if group.timestamp_nanosecond else 0
        self._poll = select.poll()  # not select(): a fleet has more sockets than FD_SETSIZE
        self._poll.register(group._socket, select.POLLIN)
        self.rx_malformed = 0  #: datagrams on the group that are not frames (dropped)
        self._rx = group._socket
        self._send_datagram = self._connect_sender()
        can.BusABC.__init__(self, channel, **kwargs)  # can_filters: attached to the socket

    # -- receive ------------------------------------------------------------------------------
    def _apply_filters(self, filters: CanFilters | None) -> None:
        self._accepts = {}
        self._kernel_masks = None if not filters else [
            (int(f["can_id"]), int(f["can_mask"])) for f in filters]
        if self._rx is not None:
            self._attach_filter()

    def _attach_filter(self) -> None:
        assert self._rx is not None
        host_only = self._multicast.host_only
        if self._own_port is None and self._kernel_masks is None and host_only is None:
            return
        try:
            prog = udp_wire.socket_filter(self._own_port, self._kernel_masks, host_only)
        except ValueError:  # too many filters for one program: the IDs in user space only
            prog = udp_wire.socket_filter(self._own_port, None, host_only)
        # not attached: the one before stays (the host-only check, attached before joining);
        # what it lets through is filtered in Python
        _attach(self._rx, prog)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        assert self._rx is not None
        flags = 0
        if timeout is not None and timeout <= 0:
            flags = socket.MSG_DONTWAIT
        elif not self._poll.poll(None if timeout is None else timeout * 1000.0):
            return None, False
        try:
            datagram, ancillary, _, _ = self._rx.recvmsg(self._multicast.max_buffer,
                                                         self._anc, flags)
        except BlockingIOError:
            return None, False
        except OSError as exc:
            raise can.CanOperationError(f"failed to receive from the socket: {exc}") from exc
        stamp = None
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS:
                sec, nsec = _TIMESPEC.unpack_from(value)
                stamp = sec + nsec * 1e-9
        try:
            msg = udp_wire.unpack(datagram, time.time() if stamp is None else stamp)
        except Exception as exc:  # anything on the group that is not a frame
            self.rx_malformed += 1
            log.debug("dropped a datagram that is not a frame (%d bytes): %s", len(datagram),
                      exc)
            return None, False
        if self._can_protocol is not CanProtocol.CAN_FD and msg.is_fd:
            return None, False
        return msg, False  # python-can applies the filters exactly (the kernel's are a superset)

    def recv_frame(self) -> tuple[int, bytes] | can.Message | None:
        """The next frame waiting that passes the filters, without waiting: ``(frame_id,
        data)`` for a classic data frame with an 11-bit ID (no ``can.Message``, no timestamp),
        a ``can.Message`` for any other frame, None when nothing is waiting. What ``recv(0)``
        returns, filtered exactly as python-can filters, but it reads past the datagrams it
        drops (not frames: ``rx_malformed``; filtered out; FD on a classic bus)."""
        assert self._rx is not None
        recv, size, accepts = self._rx.recv, self._multicast.max_buffer, self._accepts
        while True:
            try:
                datagram = recv(size, socket.MSG_DONTWAIT)
            except BlockingIOError:
                return None
            except OSError as exc:
                raise can.CanOperationError(f"failed to receive from the socket: {exc}") \
                    from exc
            frame = udp_wire.classic(datagram)
            if frame is not None:
                ok = accepts.get(frame[0])
                if ok is None:
                    ok = accepts[frame[0]] = self._matches_filters(can.Message(
                        arbitration_id=frame[0], is_extended_id=False, check=False))
                if ok:
                    return frame
                continue
            try:
                msg = udp_wire.unpack(datagram, time.time())
            except Exception as exc:  # anything on the group that is not a frame
                self.rx_malformed += 1
                log.debug("dropped a datagram that is not a frame (%d bytes): %s",
                          len(datagram), exc)
                continue
            if (self._can_protocol is CanProtocol.CAN_FD or not msg.is_fd) \
                    and self._matches_filters(msg):
                return msg

    # -- send ---------------------------------------------------------------------------------
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self._can_protocol is not CanProtocol.CAN_FD and msg.is_fd:
            raise can.CanOperationError("cannot send FD message over bus with CAN FD disabled")
        if timeout != self._tx_timeout:
            self._tx_timeout = timeout
            self._tx.settimeout(timeout)
        self._sendto(udp_wire.pack(msg))

    def send_frame(self, frame_id: int, data: bytes) -> None:
        """Send a classic data frame with an 11-bit ID: what ``send(can.Message(
        arbitration_id=frame_id, data=data, is_extended_id=False))`` sends, faster."""
        self._sendto(udp_wire.pack_classic(frame_id, data))

    def frame_writer(self, held: list[bytes] | None = None) -> Callable[[int, bytes], None]:
        """``send_frame`` as one function: the datagram is a prefix from the process' table
        (:func:`udp_wire.classic_prefixes`), the data and the tail, handed to the socket in
        one call (no ``can.Message``, no method layers); the same bytes as ``send_frame``.
        Raises ``can.CanError`` as ``send`` does. ``held``: the datagrams are appended there
        instead, for :meth:`send_held` to send in order later (one burst of system calls)."""
        prefixes, tail, put = udp_wire.PREFIXES, udp_wire.CLASSIC_TAIL, self._send_datagram
        send_frame = self.send_frame
        if held is not None:
            hold = held.append

            def write_later(frame_id: int, data: bytes) -> None:
                try:
                    hold(prefixes[frame_id][len(data)] + data + tail)
                except (KeyError, IndexError):
                    fast = 0 <= frame_id <= 0x7FF and len(data) <= 8
                    hold(udp_wire.classic_prefixes(frame_id)[len(data)] + data + tail if fast
                         else udp_wire.pack_classic(frame_id, data))

            return write_later

        def write(frame_id: int, data: bytes) -> None:
            try:
                datagram = prefixes[frame_id][len(data)] + data + tail
            except (KeyError, IndexError):  # first frame of an ID, or not a fast one
                if not 0 <= frame_id <= 0x7FF or len(data) > 8:
                    send_frame(frame_id, data)
                    return
                datagram = udp_wire.classic_prefixes(frame_id)[len(data)] + data + tail
            try:
                sent = put(datagram)
            except TimeoutError:
                raise can.CanTimeoutError() from None
            except OSError as error:
                raise can.CanOperationError(f"failed to send via socket: {error}") from error
            if sent < len(datagram):
                raise can.CanTimeoutError()

        return write

    def send_held(self, held: list[bytes]) -> int:
        """Send the datagrams a ``frame_writer(held)`` held, in order, and empty ``held``;
        returns how many the socket refused (each logged at debug level)."""
        put, refused = self._send_datagram, 0
        for datagram in held:
            try:
                if put(datagram) < len(datagram):
                    refused += 1
            except OSError as error:
                refused += 1
                log.debug("transmit failed: %s", error)
        held.clear()
        return refused

    def _connect_sender(self) -> Callable[[bytes], int]:
        """What hands a datagram to the group: the own sending socket connected to the group
        (the kernel keeps the route and the address, no address to parse per frame), or,
        when the socket also receives (hop limit > 0, IPv6), ``sendto``."""
        tx, dest = self._tx, self._dest
        if tx is not self._rx:
            try:
                tx.connect(dest)
                return tx.send
            except OSError as error:  # pragma: no cover - loopback multicast connects
                log.debug("sending socket not connected: %s", error)
        return lambda datagram: tx.sendto(datagram, dest)

    def _sendto(self, datagram: bytes) -> None:
        try:
            sent = self._tx.sendto(datagram, self._dest)
        except TimeoutError:
            raise can.CanTimeoutError() from None
        except OSError as error:
            raise can.CanOperationError(f"failed to send via socket: {error}") from error
        if sent < len(datagram):
            raise can.CanTimeoutError()

    def shutdown(self) -> None:
        super().shutdown()
        if self._tx is not self._rx:
            self._tx.close()
