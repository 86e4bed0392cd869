"""The lean udp_multicast wire path packs and parses exactly what python-can does."""

from __future__ import annotations

import random
import struct

import can
import pytest
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from lowerbase.transport import udp_wire


def _messages(seed: int, count: int) -> list[can.Message]:
    rng = random.Random(seed)
    out = []
    for _ in range(count):
        frame_id = rng.choice([0, 1, 0x7F, 0x80, 0xFF, 0x100, 0x7FF, rng.randrange(0x800)])
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(9)))
        out.append(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
    return out


def test_pack_classic_is_python_cans_datagram() -> None:
    for msg in _messages(1, 3000):
        want = pack_message(msg)
        assert udp_wire.pack_classic(msg.arbitration_id, bytes(msg.data)) == want
        assert udp_wire.pack(msg) == want


def test_classic_prefixes_make_python_cans_datagram() -> None:
    """The frame writer's pieces: prefix + data + tail is python-can's datagram (3000 random
    classic frames, DLC 0-8); only 11-bit IDs have prefixes."""
    for msg in _messages(2, 3000):
        prefix = udp_wire.classic_prefixes(msg.arbitration_id)[msg.dlc]
        assert prefix + bytes(msg.data) + udp_wire.CLASSIC_TAIL == pack_message(msg)
    assert udp_wire.classic_prefixes(0x7FF) is udp_wire.classic_prefixes(0x7FF)  # one table
    assert len(udp_wire.classic_prefixes(0x10)) == 9
    for frame_id in (-1, 0x800):
        with pytest.raises(ValueError):
            udp_wire.classic_prefixes(frame_id)


@pytest.mark.parametrize("msg", [
    can.Message(arbitration_id=0x1ABCDEF, data=b"\x01", is_extended_id=True),
    can.Message(arbitration_id=0x10, is_remote_frame=True, dlc=4, is_extended_id=False),
    can.Message(arbitration_id=0x10, data=bytes(12), is_fd=True, bitrate_switch=True,
                is_extended_id=False),
    can.Message(arbitration_id=0x10, data=b"\x01", channel="can0", is_extended_id=False),
    can.Message(timestamp=12.5, arbitration_id=0x10, data=b"\x01", is_extended_id=False),
    can.Message(is_error_frame=True, is_extended_id=False),
])
def test_other_frames_are_packed_and_parsed_by_python_can(msg: can.Message) -> None:
    datagram = udp_wire.pack(msg)
    assert datagram == pack_message(msg)
    got = udp_wire.unpack(datagram, 3.25)
    assert got.equals(unpack_message(datagram, replace={"timestamp": 3.25}, check=True))


def test_unpack_matches_python_can() -> None:
    for msg in _messages(2, 3000):
        datagram = pack_message(msg)
        got = udp_wire.unpack(datagram, 7.5)
        want = unpack_message(datagram, replace={"timestamp": 7.5}, check=True)
        assert got.equals(want), (got, want)
        assert isinstance(got.data, bytearray) and got.dlc == len(got.data)


@pytest.mark.parametrize("datagram", [
    b"", b"\x8b", b"garbage" * 10,
    pack_message(can.Message(arbitration_id=0x10, data=b"\x01\x02"))[:-3],  # truncated
    pack_message(can.Message(arbitration_id=0x10, data=b"\x01\x02")).replace(
        b"\xa3dlc\x02", b"\xa3dlc\x09"),  # DLC beyond its data and beyond 8
])
def test_unpack_refuses_what_is_not_a_frame(datagram: bytes) -> None:
    with pytest.raises(Exception):  # noqa: B017 - whatever msgpack or can.Message raises
        udp_wire.unpack(datagram, 0.0)


# -- the socket filter, run by an independent classic-BPF interpreter ---------------------


PACKET_MULTICAST = 2  # linux/if_packet.h: a multicast packet from the network


def _run_bpf(prog: list[udp_wire.Insn], packet: bytes, pkttype: int = udp_wire.PACKET_LOOPBACK,
             ifindex: int = 1) -> int:
    """A minimal classic-BPF interpreter (the opcodes socket_filter uses). ``pkttype`` and
    ``ifindex``: the ancillary values (SKF_AD_PKTTYPE, SKF_AD_IFINDEX) of the packet."""
    a = x = pc = 0
    while True:
        code, jt, jf, k = prog[pc]
        pc += 1
        cls = code & 0x07
        if code == 0x80:  # ld len
            a = len(packet)
        elif code == 0x20 and k >= 0xFFFFF000:  # ld ancillary
            a = {0xFFFFF004: pkttype, 0xFFFFF008: ifindex}[k]
        elif cls == 0x00:  # ld abs
            size = {0x00: 4, 0x08: 2, 0x10: 1}[code & 0x18]
            if k + size > len(packet):
                return 0  # out of bounds: the kernel drops the packet
            a = int.from_bytes(packet[k:k + size], "big")
        elif code == 0x54:
            a &= k
        elif code == 0x07:
            x = a
        elif code == 0x87:
            a = x
        elif code == 0x05:
            pc += k
        elif code in (0x15, 0x35):
            hit = a == k if code == 0x15 else a >= k
            pc += jt if hit else jf
        elif code == 0x06:
            return k
        else:
            raise AssertionError(f"opcode {code:#x}")


def _udp(payload: bytes, source_port: int = 40000) -> bytes:
    return struct.pack(">HHHH", source_port, 43113, 8 + len(payload), 0) + payload


FILTERS = [{"can_id": 0x010, "can_mask": 0x7FF}, {"can_id": 0x100, "can_mask": 0x700},
           {"can_id": 0x1ABCDE0, "can_mask": 0x1FFFFFF0, "extended": True}]


def _software_match(msg: can.Message) -> bool:
    bus = can.Bus(interface="virtual", channel="test_udp_wire", can_filters=FILTERS)
    try:
        return bus._matches_filters(msg)
    finally:
        bus.shutdown()


def test_socket_filter_drops_own_datagrams_only() -> None:
    prog = udp_wire.socket_filter(41000, None)
    datagram = pack_message(can.Message(arbitration_id=0x10, data=b"\x01"))
    assert _run_bpf(prog, _udp(datagram, 41000)) == 0
    assert _run_bpf(prog, _udp(datagram, 41001)) != 0
    assert _run_bpf(prog, _udp(b"x", 41001)) != 0  # user space counts what is not a frame


@pytest.mark.parametrize("masks", [None, [(0x10, 0x7FF)]])
def test_socket_filter_host_only_drops_what_other_hosts_send(
        masks: list[tuple[int, int]] | None) -> None:
    """Kept: anything that arrived on loopback (index 1 here) and the copies of this host's
    own multicast sends on another interface (index 4); dropped: multicast from the network."""
    prog = udp_wire.socket_filter(41000, masks, host_only=1)
    datagram = _udp(pack_message(can.Message(arbitration_id=0x10, data=b"\x01")))
    assert _run_bpf(prog, datagram, PACKET_MULTICAST, ifindex=1) != 0
    assert _run_bpf(prog, datagram, 0, ifindex=1) != 0  # PACKET_HOST, as loopback delivers
    assert _run_bpf(prog, datagram, udp_wire.PACKET_LOOPBACK, ifindex=4) != 0
    assert _run_bpf(prog, datagram, PACKET_MULTICAST, ifindex=4) == 0
    assert _run_bpf(prog, datagram, 0, ifindex=4) == 0
    assert _run_bpf(prog, _udp(b"x"), PACKET_MULTICAST, ifindex=4) == 0  # not even to count
    assert _run_bpf(prog, _udp(b"x", 41000), udp_wire.PACKET_LOOPBACK, ifindex=4) == 0  # own
    many = udp_wire.socket_filter(41000, [(i, 0x7FF) for i in range(48)], host_only=1)
    assert _run_bpf(many, datagram, PACKET_MULTICAST, ifindex=4) == 0
    assert _run_bpf(many, datagram, udp_wire.PACKET_LOOPBACK, ifindex=4) != 0


def test_socket_filter_keeps_what_python_can_filters_keep() -> None:
    prog = udp_wire.socket_filter(None, [(f["can_id"], f["can_mask"]) for f in FILTERS])
    rng = random.Random(3)
    ids = [0x10, 0x11, 0x100, 0x1FF, 0x200, 0x7FF, 0x0, 0x7F, 0x80, 0xFF]
    msgs = [can.Message(arbitration_id=i, data=b"\x01\x02", is_extended_id=False) for i in ids]
    msgs += [can.Message(arbitration_id=i, data=b"", is_extended_id=True)
             for i in (0x1ABCDE5, 0x1ABCDF5, 0x10, 0x100, 0xFFFF, 0x10000)]
    msgs += _messages(4, 500)
    msgs += [can.Message(arbitration_id=rng.randrange(1 << 29), is_extended_id=True)
             for _ in range(200)]
    kept = dropped = 0
    for msg in msgs:
        verdict = _run_bpf(prog, _udp(pack_message(msg)))
        want = _software_match(msg)
        if want:
            assert verdict != 0, msg  # the kernel never drops what the filters accept
        # the kernel drops every frame whose ID no filter accepts (the extended flag aside)
        id_ok = any((f["can_id"] ^ msg.arbitration_id) & f["can_mask"] == 0 for f in FILTERS)
        assert (verdict != 0) == id_ok, msg
        kept += verdict != 0
        dropped += verdict == 0
    assert kept > 20 and dropped > 500
    # another layout (a timestamp that is an int, a short datagram) is left to user space
    odd = pack_message(can.Message(arbitration_id=0x300, data=b"")).replace(
        b"\xcb" + bytes(8), b"\xcf" + bytes(8))
    assert _run_bpf(prog, _udp(odd)) != 0
    assert _run_bpf(prog, _udp(b"\x8b\xa9")) != 0


def test_many_filters() -> None:
    """Up to MAX_KERNEL_FILTERS filters run in the kernel; more are left to user space."""
    ids = list(range(0x100, 0x100 + 2 * udp_wire.MAX_KERNEL_FILTERS, 2))
    prog = udp_wire.socket_filter(41000, [(i, 0x7FF) for i in ids])
    for frame_id in range(0x100, 0x100 + 2 * udp_wire.MAX_KERNEL_FILTERS + 4):
        datagram = _udp(pack_message(can.Message(arbitration_id=frame_id, data=b"\x01")))
        assert (_run_bpf(prog, datagram) != 0) == (frame_id in ids)
    prog = udp_wire.socket_filter(41000, [(i, 0x7FF) for i in range(200)])
    datagram = pack_message(can.Message(arbitration_id=0x300, data=b""))
    assert _run_bpf(prog, _udp(datagram)) != 0
    assert _run_bpf(prog, _udp(datagram, 41000)) == 0
