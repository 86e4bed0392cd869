"""The emulator's runner and the driver's BusLink listen only to the catalog IDs of the other
side: foreign frames on a shared bus never reach them (on udp_multicast: dropped in the kernel),
while an unfiltered bus (what decode, record and the conformance suite open) sees everything."""

from __future__ import annotations

import itertools
import socket
from typing import Any

import can

from benchmarks.busload_proc import foreign_ids
from lowerbase.clock import SimClock
from lowerbase.driver.links import BusLink, listen_to_lower, upper_listens_to
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import bus_sender, listen_to_upper, lower_listens_to, run
from lowerbase.protocol.codec import default_codec
from lowerbase.transport import open_bus
from lowerbase.transport.udp_wire import unpack

CODEC = default_codec()
UPPER = {m.frame_id for m in CODEC if "Upper" in m.senders}
LOWER = {m.frame_id for m in CODEC if "Lower" in m.senders}
HEARTBEAT = CODEC.message("Heartbeat").frame_id
MOTION = CODEC.message("MotionCommand").frame_id
WHEEL = CODEC.message("WheelFeedback").frame_id
FOREIGN = [MOTION ^ 1, WHEEL ^ 0x400, 0x7F0, 0x555]  # none in the catalog
_channels = itertools.count()


def _std(frame_id: int, extended: bool = False) -> can.Message:
    return can.Message(arbitration_id=frame_id, data=bytes(8), is_extended_id=extended)


def test_the_listened_ids_are_the_other_sides_catalog_ids() -> None:
    assert set(lower_listens_to(CODEC)) == UPPER | {HEARTBEAT}  # Heartbeats: PeerMonitor
    assert set(upper_listens_to()) == LOWER
    assert UPPER and LOWER and not UPPER & LOWER
    near, far = foreign_ids(CODEC)  # what the benchmark's foreign device sends
    catalog = UPPER | LOWER
    assert not (set(near) | set(far)) & catalog
    assert len(near) + len(far) + len(catalog) == 0x800
    assert all(bin(i ^ min(catalog, key=lambda c: bin(c ^ i).count("1"))).count("1") == 1
               for i in near)
    assert not set(FOREIGN) & catalog


def _kernel_ids(bus: Any, until: int) -> list[int]:
    """IDs of the datagrams the kernel delivered to ``bus``'s receive socket, up to ``until``."""
    got: list[int] = []
    bus._rx.settimeout(5.0)
    while not got or got[-1] != until:
        try:
            got.append(unpack(bus._rx.recv(4096), 0.0).arbitration_id)
        except socket.timeout:  # noqa: UP041  # 3.10: socket.timeout is not TimeoutError
            break
    return got


def test_udp_multicast_drops_foreign_ids_in_the_kernel(udp_bus_config: dict[str, Any]) -> None:
    lower = open_bus(udp_bus_config)  # the emulator's side
    upper = open_bus(udp_bus_config)  # the driver's side
    recorder = open_bus(udp_bus_config)  # decode / record / conformance: no filters
    sender = open_bus(udp_bus_config)
    try:
        assert listen_to_upper(lower, CODEC) and listen_to_lower(upper)
        sent = [*FOREIGN, MOTION, WHEEL, FOREIGN[0], HEARTBEAT]
        for frame_id in sent:
            sender.send(_std(frame_id))
        assert _kernel_ids(lower, HEARTBEAT) == [MOTION, HEARTBEAT]
        assert _kernel_ids(upper, HEARTBEAT) == [WHEEL, HEARTBEAT]
        assert _kernel_ids(recorder, HEARTBEAT) == sent  # everything, in order
    finally:
        for bus in (lower, upper, recorder, sender):
            bus.shutdown()


def test_udp_multicast_still_delivers_foreign_frames_on_a_catalog_id(
        udp_bus_config: dict[str, Any]) -> None:
    """An extended frame whose ID equals a catalog ID arrives (it is counted as not classic
    by its owner), the standard one too; one on a foreign ID does not."""
    lower = open_bus(udp_bus_config)
    sender = open_bus(udp_bus_config)
    try:
        listen_to_upper(lower, CODEC)
        for msg in (_std(FOREIGN[0], extended=True), _std(MOTION, extended=True), _std(MOTION)):
            sender.send(msg)
        got = []
        while (msg := lower.recv(2.0)) is not None:
            got.append((msg.arbitration_id, msg.is_extended_id))
            if not msg.is_extended_id:
                break
        assert got == [(MOTION, True), (MOTION, False)]
    finally:
        lower.shutdown()
        sender.shutdown()


def _arrived(config: dict[str, Any], sent: list[can.Message], probe: can.BusABC) -> None:
    """Send ``sent`` and wait until an unfiltered ``probe`` on the group has the last one:
    loopback multicast delivers a datagram to every member socket in one pass, so every bus
    on the group holds them all by then."""
    sender = open_bus(config)
    try:
        for msg in sent:
            sender.send(msg)
    finally:
        sender.shutdown()
    last = sent[-1].arbitration_id
    while (msg := probe.recv(5.0)) is not None and msg.arbitration_id != last:
        pass
    assert msg is not None


def _run_mcu(config: dict[str, Any], catalog_filter: bool, user_filters: Any = None) -> Mcu:
    bus, probe = open_bus(config), open_bus(config)
    if user_filters is not None:
        bus.set_filters(user_filters)
    clock = SimClock()
    mcu = Mcu(load_profile(), clock, bus_sender(bus))
    try:
        motion = can.Message(arbitration_id=MOTION, data=CODEC.encode(
            "MotionCommand", {"Linear": 0.1, "Angular": 0.0, "Mode": 0, "Counter": 0}),
            is_extended_id=False)
        _arrived(config, [*map(_std, FOREIGN), motion], probe)
        run(mcu, bus, clock, duration=0.05, catalog_filter=catalog_filter)
    finally:
        bus.shutdown()
        probe.shutdown()
    return mcu


def test_the_emulator_runner_listens_to_the_upper_side_only(
        udp_bus_config: dict[str, Any]) -> None:
    mcu = _run_mcu(udp_bus_config, catalog_filter=True)
    assert mcu.stats["rx_frames"] == 1 and mcu.stats["rx_unknown_id"] == 0
    assert mcu.stats["rx_during_boot"] == 1  # the MotionCommand arrived (during the boot)
    unfiltered = _run_mcu(udp_bus_config, catalog_filter=False)
    assert unfiltered.stats["rx_frames"] == 1 + len(FOREIGN)
    assert unfiltered.stats["rx_unknown_id"] == len(FOREIGN)


def test_the_emulator_runner_keeps_the_users_filters(udp_bus_config: dict[str, Any]) -> None:
    mcu = _run_mcu(udp_bus_config, catalog_filter=True,
                   user_filters=[{"can_id": 0, "can_mask": 0}])
    assert mcu.stats["rx_unknown_id"] == len(FOREIGN)


def test_buses_that_filter_in_python_are_left_unfiltered() -> None:
    """python-can's software filter ends ``recv(0)`` at the first filtered frame (the runner's
    simulated-clock drain would stop there): such buses get no catalog filter."""
    bus = can.Bus(interface="virtual", channel=f"catalog-filters-{next(_channels)}")
    try:
        assert not listen_to_upper(bus, CODEC) and not listen_to_lower(bus)
        assert bus.filters is None
    finally:
        bus.shutdown()


def test_the_driver_link_delivers_the_lower_sides_frames_only(
        udp_bus_config: dict[str, Any]) -> None:
    sent = [*FOREIGN, MOTION, WHEEL, HEARTBEAT]
    for catalog_filter, config_filters, expected in (
            (True, None, [WHEEL, HEARTBEAT]),
            (False, None, sent),
            (True, [{"can_id": 0, "can_mask": 0}], sent)):
        config = dict(udp_bus_config)
        if config_filters is not None:
            config["can_filters"] = config_filters
        link = BusLink(config, clock=SimClock(), catalog_filter=catalog_filter)
        probe = open_bus(udp_bus_config)
        try:
            _arrived(udp_bus_config, [_std(i) for i in sent], probe)
            got: list[int] = []
            for _ in range(20):  # more polls than frames: each poll takes at most one
                link.poll(lambda fid, data, got=got: got.append(fid), timeout=0.0)
            assert got == expected, (catalog_filter, config_filters)
        finally:
            link.close()
            probe.shutdown()
