"""How a lower computer meets its bus: the MCU's ``send`` callback (:func:`bus_sender`) and
the kernel filters that keep a full bus' foreign frames away from it (:func:`listen_to_upper`).
Used by :mod:`.runner` (one chassis, a fleet) and by ``lowerbase emulate``."""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection

import can

from lowerbase.protocol.codec import Codec

log = logging.getLogger(__name__)


def bus_sender(
    bus: can.BusABC, mcu_stats: Callable[[str], None] | None = None,
    on_sent: Callable[[int, bytes], None] | None = None,
    sent_ids: Collection[int] | None = None, held: list[bytes] | None = None,
) -> Callable[[int, bytes], None]:
    """An Mcu ``send`` callback writing to ``bus``; transmit errors are counted, not raised.

    ``on_sent`` sees every frame that went out (e.g. a PeerMonitor's ``on_sent``), or only
    those with an ID in ``sent_ids`` (a PeerMonitor reads only Heartbeats). On udp_multicast
    a frame is one call into the bus' ``frame_writer`` (no ``can.Message``); with ``held``
    its datagrams wait there for :func:`send_held` (a fleet sends each chassis' in one go)."""
    writer = getattr(bus, "frame_writer", None)
    if writer is not None:
        write: Callable[[int, bytes], None] = writer(held)
    else:
        def write(frame_id: int, data: bytes) -> None:
            bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
    watched = None if sent_ids is None else frozenset(sent_ids)

    def send(frame_id: int, data: bytes) -> None:
        try:
            write(frame_id, data)
        except can.CanError as exc:
            if mcu_stats is not None:
                mcu_stats("tx_errors")
            log.debug("transmit failed: %s", exc)
            return
        if on_sent is not None and (watched is None or frame_id in watched):
            on_sent(frame_id, data)

    return send


#: a filter mask that compares the whole ID (11 or 29 bits) and ignores the extended flag, so
#: a foreign extended frame on a catalog ID still arrives to be counted as not classic
FULL_ID_MASK = 0x1FFFFFFF


def filters_in_kernel(bus: object) -> bool:
    """Whether ``bus`` drops filtered frames before they reach the process (udp_multicast's
    socket filter, SocketCAN's CAN_RAW_FILTER). Other buses filter in python-can, where
    ``recv(0)`` returns None at a filtered frame with more waiting: they are left unfiltered."""
    return type(bus).__name__ in ("GroupOnlyMulticastBus", "SocketcanBus")


def lower_listens_to(codec: Codec) -> list[int]:
    """The IDs a lower computer reads: every frame the upper side sends, and Heartbeats (a
    second lower computer on the bus is noticed by them)."""
    return sorted({m.frame_id for m in codec if "Upper" in m.senders}
                  | {codec.message("Heartbeat").frame_id})


def listen_to_upper(bus: can.BusABC, codec: Codec) -> bool:
    """Set ``bus``'s filters to :func:`lower_listens_to` unless it has filters already (the
    user's) or cannot filter in the kernel (:func:`filters_in_kernel`); True when set."""
    if getattr(bus, "filters", None) or not filters_in_kernel(bus):
        return False
    bus.set_filters([{"can_id": i, "can_mask": FULL_ID_MASK} for i in lower_listens_to(codec)])
    return True
