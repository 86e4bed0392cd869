"""Run an :class:`~lowerbase.firmware_model.mcu.Mcu` against a python-can bus.

Real time: frames are handled as they arrive and the control loop keeps its period (the
deadline advances by exactly one period per step, so periodic frames keep their cycle).
Simulated time: each step drains what the bus holds, then the clock jumps one period.

Given a :class:`~lowerbase.transport.peers.PeerMonitor` (fed with what the MCU sends through
``bus_sender(..., on_sent=...)``), the runner warns once, and counts ``two_lower_computers`` in
the MCU's stats, when another lower computer's Heartbeats share the bus.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import can

from lowerbase.clock import Clock, SimClock
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.transport import is_catalog_frame
from lowerbase.transport.peers import PeerMonitor

log = logging.getLogger(__name__)


def bus_sender(
    bus: can.BusABC, mcu_stats: Callable[[str], None] | None = None,
    on_sent: Callable[[int, bytes], None] | None = None,
) -> Callable[[int, bytes], None]:
    """An Mcu ``send`` callback writing to ``bus``; transmit errors are counted, not raised.

    ``on_sent`` sees every frame that went out (e.g. a PeerMonitor's ``on_sent``)."""

    def send(frame_id: int, data: bytes) -> None:
        try:
            bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
        except can.CanError as exc:
            if mcu_stats is not None:
                mcu_stats("tx_errors")
            log.debug("transmit failed: %s", exc)
            return
        if on_sent is not None:
            on_sent(frame_id, data)

    return send


def _receive(mcu: Mcu, msg: can.Message, peers: PeerMonitor | None) -> None:
    if is_catalog_frame(msg):
        data = bytes(msg.data)
        if peers is not None and peers.on_frame(msg.arbitration_id, data, mcu.clock.now()):
            mcu.stats["two_lower_computers"] += 1
            log.warning("%s", peers.warning)
        mcu.receive(msg.arbitration_id, data)
    else:  # counted like any frame the catalog does not know, and ignored
        mcu.stats["rx_frames"] += 1
        mcu.stats["rx_not_classic"] += 1


def run(
    mcu: Mcu,
    bus: can.BusABC,
    clock: Clock,
    *,
    duration: float | None = None,
    stop: threading.Event | None = None,
    on_step: Callable[[Mcu], None] | None = None,
    peers: PeerMonitor | None = None,
) -> None:
    """Run until ``duration`` [s] of (simulated or real) time has passed or ``stop`` is set.

    ``peers``: warn once when a second lower computer is on the bus (see the module)."""
    stop = stop or threading.Event()
    start = clock.now()
    deadline = start
    while not stop.is_set():
        if duration is not None and clock.now() - start >= duration - 1e-9:
            break
        deadline += mcu.dt
        if isinstance(clock, SimClock):
            while (msg := bus.recv(0.0)) is not None:
                _receive(mcu, msg, peers)
            mcu.step()
            clock.advance(mcu.dt)
        else:
            while True:
                remaining = deadline - clock.now()
                msg = bus.recv(max(remaining, 0.0)) if remaining > 0 else bus.recv(0.0)
                if msg is None:
                    break
                _receive(mcu, msg, peers)
            mcu.step()
            if clock.now() - deadline > 1.0:  # overloaded (or suspended): do not burst-catch-up
                deadline = clock.now()
        if on_step is not None:
            on_step(mcu)
