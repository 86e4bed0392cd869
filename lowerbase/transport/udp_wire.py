"""python-can's udp_multicast wire format, packed and parsed without a dict per frame.

A python-can udp_multicast datagram is one msgpack map of a ``can.Message``'s fields, always
in the same order (``can.interfaces.udp_multicast.utils.pack_message``). For the frames every
lowerbase side sends (classic, standard 11-bit ID, no channel name) everything but the ID, the
DLC and the data is the same on every frame, so :func:`pack_classic` joins pre-packed pieces:
the bytes are exactly ``pack_message(can.Message(arbitration_id=i, data=d,
is_extended_id=False))`` (tests/transport/test_udp_wire.py checks it against python-can), so
python-can's own tools (``can.logger``, ``can.viewer``) interoperate. :func:`unpack` reads that
layout directly and hands anything else to python-can's msgpack path.

:func:`socket_filter` builds the classic-BPF program that the multicast bus attaches to its
receive socket: the kernel drops this bus's own datagrams (looped back by multicast) and,
given ``can_filters``, datagrams in this layout whose ID no filter accepts, before they cost
the process a system call; with hop limit 0 it first drops every datagram that another host
sent.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

import can
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

_TS = b"\x8b\xa9timestamp\xcb"  # fixmap(11), "timestamp", float64
_ID_KEY = b"\xaearbitration_id"
_MIDDLE = (b"\xaeis_extended_id\xc2\xafis_remote_frame\xc2\xaeis_error_frame\xc2"
           b"\xa7channel\xc0\xa3dlc")
_DATA_KEY = b"\xa4data\xc4"
_TAIL = b"\xa5is_fd\xc2\xaebitrate_switch\xc2\xb5error_state_indicator\xc2"
_ZERO_TS = struct.pack(">d", 0.0)
#: offset of the ID's msgpack type byte in the datagram (its UDP payload)
ID_OFFSET = len(_TS) + 8 + len(_ID_KEY)
MAX_FAST_DLC = 64  #: longer data is packed by python-can (fixint DLC only up to 127)

_heads: dict[int, bytes] = {}


def _pack_uint(value: int) -> bytes:
    """msgpack's smallest encoding of a non-negative int below 2**32 (what msgpack-python picks)."""
    if value < 0x80:
        return bytes((value,))
    if value <= 0xFF:
        return b"\xcc" + bytes((value,))
    if value <= 0xFFFF:
        return b"\xcd" + value.to_bytes(2, "big")
    return b"\xce" + value.to_bytes(4, "big")


def _head(frame_id: int) -> bytes:
    head = _heads.get(frame_id)
    if head is None:
        head = _heads[frame_id] = _TS + _ZERO_TS + _ID_KEY + _pack_uint(frame_id) + _MIDDLE
    return head


_DLC_DATA = [bytes((n,)) + _DATA_KEY + bytes((n,)) for n in range(MAX_FAST_DLC + 1)]
#: what follows the data in every :func:`pack_classic` datagram
CLASSIC_TAIL = _TAIL
#: frame ID -> :func:`classic_prefixes` (one table for every bus of the process)
PREFIXES: dict[int, list[bytes]] = {}


def classic_prefixes(frame_id: int) -> list[bytes]:
    """The datagram of a classic frame with the 11-bit ``frame_id`` up to its data, for DLC 0
    to 8: ``pack_classic(frame_id, d) == classic_prefixes(frame_id)[len(d)] + d +
    CLASSIC_TAIL``; kept in :data:`PREFIXES` (at most 2048 IDs x 9 prefixes)."""
    if not 0 <= frame_id <= 0x7FF:
        raise ValueError(f"not an 11-bit frame ID: {frame_id}")
    prefixes = PREFIXES.get(frame_id)
    if prefixes is None:
        head = _head(frame_id)
        prefixes = PREFIXES[frame_id] = [head + dlc_data for dlc_data in _DLC_DATA[:9]]
    return prefixes


def pack_classic(frame_id: int, data: bytes) -> bytes:
    """The datagram python-can sends for ``can.Message(arbitration_id=frame_id, data=data,
    is_extended_id=False)`` (timestamp 0.0, as a fresh Message has)."""
    if 0 <= frame_id <= 0x7FF and len(data) <= MAX_FAST_DLC:
        return b"".join((_head(frame_id), _DLC_DATA[len(data)], data, _TAIL))
    return pack_message(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))


def pack(msg: can.Message) -> bytes:
    """``pack_message(msg)``, through :func:`pack_classic` when ``msg`` is a plain classic
    frame with a zero timestamp (what the emulator and the driver send)."""
    if (msg.timestamp == 0.0 and type(msg.timestamp) is float and msg.channel is None
            and not (msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame
                     or msg.is_fd or msg.bitrate_switch or msg.error_state_indicator)
            and msg.dlc == len(msg.data)):
        return pack_classic(msg.arbitration_id, bytes(msg.data))
    return pack_message(msg)


def classic(datagram: bytes) -> tuple[int, bytes] | None:
    """``(frame_id, data)`` when ``datagram`` is a classic data frame with an 11-bit ID and
    DLC 0-8 in python-can's layout (what :func:`pack_classic` sends, any timestamp); None for
    anything else (another kind of frame, or not a frame: :func:`unpack` tells them apart)."""
    n = len(datagram)
    if n > ID_OFFSET + 1 and datagram.startswith(_TS) and datagram.startswith(
            _ID_KEY, ID_OFFSET - len(_ID_KEY)):
        kind = datagram[ID_OFFSET]
        if kind < 0x80:
            frame_id, pos = kind, ID_OFFSET + 1
        elif kind == 0xCC:
            frame_id, pos = datagram[ID_OFFSET + 1], ID_OFFSET + 2
        elif kind == 0xCD:
            frame_id, pos = int.from_bytes(datagram[ID_OFFSET + 1:ID_OFFSET + 3], "big"), \
                ID_OFFSET + 3
        else:
            return None  # not a standard ID
        if frame_id <= 0x7FF and datagram.startswith(_MIDDLE, pos):
            pos += len(_MIDDLE)
            dlc = datagram[pos] if pos < n else 0xFF
            if dlc <= 8 and datagram.startswith(_DLC_DATA[dlc], pos) \
                    and n == pos + len(_DLC_DATA[dlc]) + dlc + len(_TAIL) \
                    and datagram.endswith(_TAIL):
                start = pos + len(_DLC_DATA[dlc])
                return frame_id, datagram[start:start + dlc]
    return None


def unpack(datagram: bytes, timestamp: float) -> can.Message:
    """The frame in ``datagram``, stamped ``timestamp``. Raises ``ValueError`` (or what msgpack
    raises) for a datagram that is not a valid python-can frame."""
    frame = classic(datagram)
    if frame is not None:
        frame_id, data = frame
        return can.Message(timestamp=timestamp, arbitration_id=frame_id, is_extended_id=False,
                           dlc=len(data), data=data, check=False)
    return unpack_message(datagram, replace={"timestamp": timestamp}, check=True)


# classic BPF (linux/filter.h); on a UDP socket the program sees the UDP header at offset 0
_LD_W, _LD_H, _LD_B, _LD_LEN = 0x20, 0x28, 0x30, 0x80
_JA, _JEQ, _JGE, _AND, _TAX, _TXA, _RET = 0x05, 0x15, 0x35, 0x54, 0x07, 0x87, 0x06
_UDP_HEADER = 8
# ancillary loads (SKF_AD_OFF + SKF_AD_PKTTYPE / SKF_AD_IFINDEX): the packet's type and the
# index of the interface it arrived on
_AD_PKTTYPE, _AD_IFINDEX = 0xFFFFF000 + 4, 0xFFFFF000 + 8
PACKET_LOOPBACK = 5  #: linux/if_packet.h: a copy the kernel looped back from this host's send
MAX_KERNEL_FILTERS = 48  #: more filters than this are applied in user space only
Insn = tuple[int, int, int, int]  #: (code, jump if true, jump if false, k): struct sock_filter
#: symbolic instruction: (code, k, label if true, label if false); a str alone is a label
_Sym = tuple[int, int, str | None, str | None] | str


def socket_filter(own_port: int | None, id_masks: Iterable[tuple[int, int]] | None,
                  host_only: int | None = None) -> list[Insn]:
    """A classic-BPF program for a udp_multicast receive socket.

    ``host_only`` (the loopback interface's index): first drop every datagram that did not
    come from this host, that is, that arrived on another interface than loopback and is not
    a copy of one of this host's own multicast sends (``PACKET_LOOPBACK``, made only by the
    kernel's multicast loop; a datagram from the network is ``PACKET_MULTICAST``). Then drops
    datagrams from UDP source port ``own_port`` (this bus's own sending socket), and,
    when ``id_masks`` (``(can_id, can_mask)`` pairs, python-can's filter semantics) is given,
    datagrams in python-can's layout whose ID matches none. Anything in another layout is
    kept, for user space to decide; the bus still applies the filters exactly (the extended
    flag too), so the kernel only ever drops what would be dropped anyway.
    """
    prog: list[_Sym] = []
    if host_only is not None:
        prog += [(_LD_W, _AD_PKTTYPE, None, None), (_JEQ, PACKET_LOOPBACK, "host", None),
                 (_LD_W, _AD_IFINDEX, None, None), (_JEQ, host_only, "host", None),
                 (_RET, 0, None, None), "host"]
    if own_port is not None:
        prog += [(_LD_H, 0, None, None), (_JEQ, own_port, "drop", None)]
    masks = list(id_masks) if id_masks is not None else []
    if masks and len(masks) <= MAX_KERNEL_FILTERS:
        at = _UDP_HEADER + ID_OFFSET
        prog += [(_LD_LEN, 0, None, None), (_JGE, at + 5, None, "keep")]
        for offset, chunk in _chunks(_TS, 0) + _chunks(_ID_KEY, ID_OFFSET - len(_ID_KEY)):
            load = {4: _LD_W, 2: _LD_H, 1: _LD_B}[len(chunk)]
            prog += [(load, _UDP_HEADER + offset, None, None),
                     (_JEQ, int.from_bytes(chunk, "big"), None, "keep")]
        prog += [(_LD_B, at, None, None), (_JGE, 0x80, "wide", None), (_TAX, 0, None, None),
                 (_JA, 0, "match", None)]
        for kind, load, label, fail in ((0xCC, _LD_B, "wide", "cd"), (0xCD, _LD_H, "cd", "ce"),
                                        (0xCE, _LD_W, "ce", "keep")):
            prog += [label, (_JEQ, kind, None, fail), (load, at + 1, None, None),
                     (_TAX, 0, None, None), (_JA, 0, "match", None)]
        prog.append("match")
        for can_id, can_mask in masks:
            mask = can_mask & 0xFFFFFFFF
            prog += [(_TXA, 0, None, None), (_AND, mask, None, None),
                     (_JEQ, can_id & mask, "keep", None)]
        prog.append((_RET, 0, None, None))  # no filter matched
    prog += ["keep", (_RET, 0xFFFFFFFF, None, None), "drop", (_RET, 0, None, None)]
    return _assemble(prog)


def _chunks(data: bytes, offset: int) -> list[tuple[int, bytes]]:
    out, i = [], 0
    while i < len(data):
        size = 4 if len(data) - i >= 4 else 2 if len(data) - i >= 2 else 1
        out.append((offset + i, data[i:i + size]))
        i += size
    return out


def _assemble(prog: list[_Sym]) -> list[Insn]:
    """Resolve labels into relative jumps."""
    labels: dict[str, int] = {}
    code: list[tuple[int, int, str | None, str | None]] = []
    for item in prog:
        if isinstance(item, str):
            labels[item] = len(code)
        else:
            code.append(item)
    out: list[Insn] = []
    for i, (op, k, jt, jf) in enumerate(code):
        rel_t = labels[jt] - i - 1 if jt else 0
        rel_f = labels[jf] - i - 1 if jf else 0
        if op == _JA:
            out.append((op, 0, 0, rel_t))
        else:
            if not (0 <= rel_t <= 255 and 0 <= rel_f <= 255):
                raise ValueError("socket filter too long for a conditional jump")
            out.append((op, rel_t, rel_f, k))
    return out
