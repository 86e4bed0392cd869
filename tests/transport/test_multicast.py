"""udp_multicast accepts only datagrams sent to its group; hop limit 0 stays on loopback."""

from __future__ import annotations

import select
import socket
from typing import Any

import can
from can.interfaces.udp_multicast.bus import UdpMulticastBus
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


def _raw_queue(bus: can.BusABC) -> list[bytes]:
    """The datagrams waiting in the bus's receive socket (what the kernel let through)."""
    sock = bus._rx  # type: ignore[attr-defined]
    out = []
    while True:
        try:
            out.append(sock.recv(4096, socket.MSG_DONTWAIT))
        except BlockingIOError:
            return out


def _settle(bus: can.BusABC, marker: int) -> list[can.Message]:
    """Frames ``bus`` receives up to and including the ID ``marker`` (sent last)."""
    got = []
    while (msg := bus.recv(2.0)) is not None:
        got.append(msg)
        if msg.arbitration_id == marker:
            return got
    raise AssertionError(f"marker {marker:#x} never arrived")


def test_a_bus_does_not_hear_itself_and_its_peers_hear_it(udp_bus_config: dict[str, Any]) -> None:
    a, b = open_bus(udp_bus_config), open_bus(udp_bus_config)
    try:
        a.send(_frame(0x10))
        a.send_frame(0x11, b"\x05")  # type: ignore[attr-defined]
        got = _settle(b, 0x11)
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == [(0x10, b"\x01\x02"),
                                                                   (0x11, b"\x05")]
        assert not got[0].is_extended_id and got[0].timestamp > 0  # a kernel receive time
        b.send(_frame(0x12))
        assert [m.arbitration_id for m in _settle(a, 0x12)] == [0x12]  # not its own 0x10, 0x11
    finally:
        a.shutdown()
        b.shutdown()


def test_python_cans_own_udp_multicast_bus_interoperates(udp_bus_config: dict[str, Any]) -> None:
    """The lean path's datagrams are python-can's: its own bus decodes them, and ours its."""
    ours = open_bus(udp_bus_config)
    theirs = UdpMulticastBus(channel=udp_bus_config["channel"], port=udp_bus_config["port"],
                             hop_limit=0)
    try:
        ours.send_frame(0x123, bytes(range(8)))  # type: ignore[attr-defined]
        ours.send(can.Message(arbitration_id=0x1ABCDEF, data=b"\x09", is_extended_id=True))
        got = [theirs.recv(2.0) for _ in range(2)]
        assert got[0] is not None and got[1] is not None
        assert (got[0].arbitration_id, bytes(got[0].data), got[0].is_extended_id) == \
            (0x123, bytes(range(8)), False)
        assert (got[1].arbitration_id, bytes(got[1].data), got[1].is_extended_id) == \
            (0x1ABCDEF, b"\x09", True)
        # a plain python-can bus sends on the default interface; lowerbase (hop limit 0)
        # listens on loopback only, so the peer has to send there too
        theirs._multicast._socket.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                                             socket.inet_aton("127.0.0.1"))
        theirs.send(can.Message(arbitration_id=0x321, data=b"\x07\x08", is_extended_id=False))
        msg = ours.recv(2.0)
        assert msg is not None and (msg.arbitration_id, bytes(msg.data)) == (0x321, b"\x07\x08")
    finally:
        theirs.shutdown()
        ours.shutdown()


def test_can_filters_drop_foreign_ids_in_the_kernel(udp_bus_config: dict[str, Any]) -> None:
    wanted: list[can.typechecking.CanFilter] = [
        {"can_id": 0x10, "can_mask": 0x7FF, "extended": False},
        {"can_id": 0x200, "can_mask": 0x700}]
    listener = open_bus(udp_bus_config, can_filters=wanted)
    sender = open_bus(udp_bus_config)
    try:
        for frame_id in (0x11, 0x10, 0x300, 0x2AB, 0x7FF):
            sender.send_frame(frame_id, b"\x01")  # type: ignore[attr-defined]
        sender.send(can.Message(arbitration_id=0x10, data=b"", is_extended_id=True))
        sender.send_frame(0x201, b"\x02")  # type: ignore[attr-defined]
        ids = [m.arbitration_id for m in _settle(listener, 0x201)]
        assert ids == [0x10, 0x2AB, 0x201]  # the extended 0x10 passes the kernel, not Python
        sender.send_frame(0x300, b"")  # type: ignore[attr-defined]
        sender.send_frame(0x10, b"")  # type: ignore[attr-defined]
        assert _settle(listener, 0x10)[-1].arbitration_id == 0x10
        listener.set_filters(None)  # everything again
        sender.send_frame(0x300, b"")  # type: ignore[attr-defined]
        sender.send_frame(0x301, b"")  # type: ignore[attr-defined]
        assert [m.arbitration_id for m in _settle(listener, 0x301)] == [0x300, 0x301]
        listener.set_filters(wanted)
        sender.send_frame(0x300, b"")  # type: ignore[attr-defined]
        sender.send_frame(0x10, b"")  # type: ignore[attr-defined]
        sender.send_frame(0x211, b"")  # type: ignore[attr-defined]
        assert _settle(listener, 0x211)  # then the queue holds what the kernel kept:
        sender.send_frame(0x300, b"")  # type: ignore[attr-defined]
        sender.send_frame(0x10, b"")  # type: ignore[attr-defined]
        assert _settle(listener, 0x10)
        assert _raw_queue(listener) == []
    finally:
        sender.shutdown()
        listener.shutdown()


def test_the_kernel_queue_holds_only_wanted_frames(udp_bus_config: dict[str, Any]) -> None:
    listener = open_bus(udp_bus_config, can_filters=[{"can_id": 0x10, "can_mask": 0x7FF}])
    sender = open_bus(udp_bus_config)
    try:
        for frame_id in (0x300, 0x301, 0x10, 0x302):
            sender.send_frame(frame_id, b"\x01")  # type: ignore[attr-defined]
        assert listener.recv(2.0) is not None  # the 0x10 arrived; whatever else is queued:
        queued = _raw_queue(listener)
        sender.send_frame(0x10, b"\x02")  # type: ignore[attr-defined]
        assert listener.recv(2.0) is not None
        assert queued == []  # 0x302 came after 0x10 and never reached the socket
    finally:
        sender.shutdown()
        listener.shutdown()


def test_datagrams_on_the_group_that_are_not_frames_are_counted(
        udp_bus_config: dict[str, Any]) -> None:
    bus = open_bus(udp_bus_config)
    group, port = udp_bus_config["channel"], udp_bus_config["port"]
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
            other.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
            other.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                             socket.inet_aton("127.0.0.1"))
            other.sendto(b"not msgpack \xc1", (group, port))
            other.sendto(pack_message(_frame(0x20)), (group, port))
        msg = bus.recv(2.0)
        assert msg is not None and msg.arbitration_id == 0x20
        assert bus.rx_malformed == 1  # type: ignore[attr-defined]
    finally:
        bus.shutdown()


def _raw_listener(group: str, port: int) -> socket.socket:
    """A plain socket on the group and port (loopback): the datagrams as they are."""
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    raw.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    raw.bind((group, port))
    raw.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                   socket.inet_aton(group) + socket.inet_aton("127.0.0.1"))
    raw.settimeout(2.0)
    return raw


def test_frame_writer_sends_what_python_can_sends(udp_bus_config: dict[str, Any]) -> None:
    """The lean per-frame writer (a prefix from a table, the data, the tail; one socket call)
    puts python-can's own datagram on the wire for every 11-bit ID width and DLC, the first
    and the repeated frame of an ID alike; python-can's UdpMulticastBus decodes them all.
    Longer data and a wider ID (which python-can's receiver refuses as classic frames) are
    its bytes as well."""
    group, port = udp_bus_config["channel"], udp_bus_config["port"]
    ours = open_bus(udp_bus_config)
    theirs = UdpMulticastBus(channel=group, port=port, hop_limit=0)
    raw = _raw_listener(group, port)
    frames = [(i, bytes(range(n))) for i in (0x000, 0x07F, 0x080, 0x0FF, 0x100, 0x7FF)
              for n in (0, 1, 8, 8, 3)]
    odd = [(0x7FF, bytes(12)), (0x123, bytes(64)), (0x800, b"\x01\x02")]
    try:
        write = ours.frame_writer()  # type: ignore[attr-defined]
        for frame_id, data in frames + odd:
            write(frame_id, data)
        for frame_id, data in frames + odd:
            expected = pack_message(can.Message(arbitration_id=frame_id, data=data,
                                                is_extended_id=False))
            assert raw.recv(4096) == expected, (hex(frame_id), data)
        for frame_id, data in frames:
            msg = theirs.recv(2.0)
            assert msg is not None
            assert (msg.arbitration_id, bytes(msg.data), msg.dlc, msg.is_extended_id,
                    msg.is_remote_frame, msg.is_fd) == (frame_id, data, len(data), False,
                                                        False, False)
        assert ours.recv(0.0) is None  # it does not hear itself
    finally:
        raw.close()
        theirs.shutdown()
        ours.shutdown()


def test_frame_writer_refusals_are_can_errors(udp_bus_config: dict[str, Any]) -> None:
    bus = open_bus(udp_bus_config)
    write = bus.frame_writer()  # type: ignore[attr-defined]
    bus.shutdown()  # its sockets closed: sending fails
    try:
        write(0x10, b"\x01")
    except can.CanError as exc:
        assert "failed to send" in str(exc)
    else:
        raise AssertionError("a frame on a closed bus was not refused")


def test_held_frames_are_sent_in_order_later_and_refusals_counted(
        udp_bus_config: dict[str, Any]) -> None:
    """``frame_writer(held)`` only holds the datagrams (python-can's bytes); ``send_held``
    sends them in order and empties the list; on a closed bus it counts each as refused."""
    group, port = udp_bus_config["channel"], udp_bus_config["port"]
    ours = open_bus(udp_bus_config)
    raw = _raw_listener(group, port)
    held: list[bytes] = []
    frames = [(0x10, b"\x01"), (0x7FF, bytes(8)), (0x123, b""), (0x800, b"\x02"),
              (0x10, b"\x03")]
    try:
        write = ours.frame_writer(held)  # type: ignore[attr-defined]
        for frame_id, data in frames:
            write(frame_id, data)
        raw.settimeout(0.0)
        try:
            raw.recv(4096)
            raise AssertionError("a held frame was sent at once")
        except BlockingIOError:
            pass
        assert ours.send_held(held) == 0 and held == []  # type: ignore[attr-defined]
        raw.settimeout(2.0)
        assert [raw.recv(4096) for _ in frames] == [pack_message(can.Message(
            arbitration_id=i, data=d, is_extended_id=False)) for i, d in frames]
        write(0x10, b"\x04")
        write(0x11, b"\x05")
    finally:
        raw.close()
        ours.shutdown()
    assert ours.send_held(held) == 2 and held == []  # type: ignore[attr-defined]


def _recv_frames(bus: can.BusABC, marker: int) -> list[tuple[int, bytes] | can.Message]:
    """What ``bus.recv_frame()`` returns up to the ID ``marker`` (sent last)."""
    got: list[tuple[int, bytes] | can.Message] = []
    poll = select.poll()
    poll.register(bus.fileno(), select.POLLIN)
    while poll.poll(2000):
        while (frame := bus.recv_frame()) is not None:  # type: ignore[attr-defined]
            got.append(frame)
            if isinstance(frame, tuple) and frame[0] == marker:
                return got
    raise AssertionError(f"marker {marker:#x} never arrived")


def test_recv_frame_reads_what_recv_reads_without_messages(
        udp_bus_config: dict[str, Any]) -> None:
    """python-can's own bus sends classic, extended and FD frames, a foreign ID and a datagram
    that is no frame: recv_frame gives the classic ones as (ID, data), the others as
    Messages, filtered exactly as recv filters (the extended 0x10 passes the kernel, not the
    filter), and reads past what it drops."""
    wanted: list[can.typechecking.CanFilter] = [
        {"can_id": 0x10, "can_mask": 0x7FF, "extended": False},
        {"can_id": 0x200, "can_mask": 0x700}, {"can_id": 0x1ABCDEF, "can_mask": 0x1FFFFFFF}]
    plain, lean = (open_bus(udp_bus_config, can_filters=wanted) for _ in range(2))
    theirs = UdpMulticastBus(channel=udp_bus_config["channel"], port=udp_bus_config["port"],
                             hop_limit=0)
    theirs._multicast._socket.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                                         socket.inet_aton("127.0.0.1"))
    sent = [can.Message(arbitration_id=0x10, data=b"", is_extended_id=True),
            can.Message(arbitration_id=0x10, data=bytes(range(8)), is_extended_id=False),
            can.Message(arbitration_id=0x300, data=b"\x01", is_extended_id=False),
            can.Message(arbitration_id=0x1ABCDEF, data=b"\x09", is_extended_id=True),
            can.Message(arbitration_id=0x2AB, data=bytes(range(12)), is_fd=True,
                        is_extended_id=False),
            can.Message(arbitration_id=0x201, data=b"\x02\x03", is_extended_id=False)]
    try:
        theirs._multicast._socket.sendto(b"not msgpack \xc1", (udp_bus_config["channel"],
                                                                udp_bus_config["port"]))
        for msg in sent:
            theirs.send(msg)
        by_recv = [(m.arbitration_id, bytes(m.data), m.is_extended_id, m.is_fd)
                   for m in _settle(plain, 0x201)]
        frames = _recv_frames(lean, 0x201)
        assert [(f[0], f[1], False, False) if isinstance(f, tuple) else
                (f.arbitration_id, bytes(f.data), f.is_extended_id, f.is_fd)
                for f in frames] == by_recv
        assert by_recv == [(0x10, bytes(range(8)), False, False),
                           (0x1ABCDEF, b"\x09", True, False),
                           (0x2AB, bytes(range(12)), False, True), (0x201, b"\x02\x03", False,
                                                                    False)]
        assert [type(f) for f in frames] == [tuple, can.Message, can.Message, tuple]
        assert lean.rx_malformed == 1  # type: ignore[attr-defined]
        assert lean.recv_frame() is None  # type: ignore[attr-defined]
    finally:
        theirs.shutdown()
        plain.shutdown()
        lean.shutdown()


def test_recv_frame_filters_classic_frames_in_user_space_too(
        udp_bus_config: dict[str, Any]) -> None:
    """More filters than the kernel program takes: the IDs are filtered in user space only;
    recv_frame drops what the filters refuse, and takes new filters at once."""
    many: list[can.typechecking.CanFilter] = [
        {"can_id": i, "can_mask": 0x7FF} for i in range(0x100, 0x13C)]  # 60 > 48
    lean = open_bus(udp_bus_config, can_filters=many)
    sender = open_bus(udp_bus_config)
    try:
        sender.send_frame(0x10, b"\x01")  # type: ignore[attr-defined]
        sender.send_frame(0x101, b"\x02")  # type: ignore[attr-defined]
        assert _recv_frames(lean, 0x101) == [(0x101, b"\x02")]
        lean.set_filters(None)
        sender.send_frame(0x10, b"\x03")  # type: ignore[attr-defined]
        sender.send_frame(0x101, b"\x04")  # type: ignore[attr-defined]
        assert _recv_frames(lean, 0x101) == [(0x10, b"\x03"), (0x101, b"\x04")]
    finally:
        sender.shutdown()
        lean.shutdown()
