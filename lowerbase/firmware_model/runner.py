"""Run an :class:`~lowerbase.firmware_model.mcu.Mcu` against a python-can bus.

Real time: frames are handled as they arrive and the control loop keeps its period on a
:class:`~lowerbase.clock.PacedClock` (the MCU's time advances by exactly one period per step,
so periodic frames keep their cycle and the model its time; on a
:class:`~lowerbase.clock.ScaledClock`, ``emulate --speed K``, the waits are K times shorter).
A loop the host runs late catches up period by period, up to ``CATCH_UP``; further behind,
its time slips, counted (the Heartbeat's Overruns, ``PacedClock.overruns``) and warned of.
Simulated time: each step drains what the bus holds, then the clock jumps one period.
:func:`run_fleet` steps N chassis on one clock in one process, each on its own bus
(:func:`fleet_bus_configs`): one ``epoll`` wait per period for all, then one step each.

Given a :class:`~lowerbase.transport.peers.PeerMonitor` (fed with the Heartbeats the MCU
sends, ``bus_sender(..., on_sent=...)``), the runner warns once, and counts
``two_lower_computers``, when another lower computer's Heartbeats share the bus. Both runners
listen only to what a lower computer reads (:func:`listen_to_upper`) unless the bus has
filters of its own: on udp_multicast (and SocketCAN) other devices' frames are dropped in the
kernel, however full the bus is. A frame on a listened ID that is not a classic frame
(extended, remote) still arrives and is counted as ``rx_not_classic``.
"""

from __future__ import annotations

import dataclasses
import logging
import selectors
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import can

from lowerbase.clock import Clock, PacedClock, SimClock
from lowerbase.errors import ConfigError
from lowerbase.firmware_model.bus_io import FULL_ID_MASK as FULL_ID_MASK
from lowerbase.firmware_model.bus_io import bus_sender as bus_sender
from lowerbase.firmware_model.bus_io import filters_in_kernel as filters_in_kernel
from lowerbase.firmware_model.bus_io import listen_to_upper
from lowerbase.firmware_model.bus_io import lower_listens_to as lower_listens_to
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import Profile
from lowerbase.transport import is_catalog_frame
from lowerbase.transport.peers import PeerMonitor

log = logging.getLogger(__name__)

#: periods a chassis of a fleet steps at a time on the simulated clock (see :func:`run_fleet`;
#: 0.2 s at 200 Hz, under half the default command timeout)
SIM_BLOCK = 40
#: fleets from this size up run in blocks by default: every fleet, since a block runs through
#: ``Mcu.advance``'s compiled runs (benchmarks/bench_fleet.py: about 2x at 1, 10 and 300 chassis)
SIM_BLOCK_FLEET = 1


def _receive(mcu: Mcu, msg: can.Message | tuple[int, bytes], peers: PeerMonitor | None
             ) -> None:
    """A received frame to ``mcu``: a ``can.Message`` or ``(frame_id, data)`` of a classic
    frame (``GroupOnlyMulticastBus.recv_frame``)."""
    if isinstance(msg, tuple):
        frame_id, data = msg
    elif is_catalog_frame(msg):
        frame_id, data = msg.arbitration_id, bytes(msg.data)
    else:  # counted like any frame the catalog does not know, and ignored
        mcu.stats["rx_frames"] += 1
        mcu.stats["rx_not_classic"] += 1
        return
    if peers is not None and peers.on_frame(frame_id, data, mcu.clock.now()):
        mcu.stats["two_lower_computers"] += 1
        log.warning("%s", peers.warning)
    mcu.receive(frame_id, data)


def _drain(mcu: Mcu, bus: can.BusABC, peers: PeerMonitor | None) -> None:
    """Hand ``mcu`` every frame waiting on ``bus``, without waiting: on udp_multicast through
    ``recv_frame`` (no ``can.Message``; it reads past datagrams it drops), else ``recv(0)``."""
    read = getattr(bus, "recv_frame", None)
    if read is None:
        while (msg := bus.recv(0.0)) is not None:
            _receive(mcu, msg, peers)
        return
    while (frame := read()) is not None:
        _receive(mcu, frame, peers)


def run(
    mcu: Mcu, bus: can.BusABC, clock: Clock, *, duration: float | None = None,
    stop: threading.Event | None = None, on_step: Callable[[Mcu], None] | None = None,
    peers: PeerMonitor | None = None, catalog_filter: bool = True,
) -> None:
    """Run until ``duration`` [s] of (simulated or real) time has passed or ``stop`` is set.

    ``peers``: warn once when a second lower computer is on the bus (see the module).
    ``catalog_filter``: listen to the upper side's IDs only (:func:`listen_to_upper`)."""
    if catalog_filter:
        listen_to_upper(bus, mcu.codec)
    stop = stop or threading.Event()
    if isinstance(clock, SimClock):
        start = clock.now()
        while not stop.is_set():
            if duration is not None and clock.now() - start >= duration - 1e-9:
                break
            _drain(mcu, bus, peers)
            mcu.step()
            clock.advance(mcu.dt)
            if on_step is not None:
                on_step(mcu)
        return
    pace, owned = paced(clock), mcu.clock
    mcu.clock = pace
    try:
        start = deadline = pace.now()
        while not stop.is_set():
            if duration is not None and pace.now() - start >= duration - 1e-9:
                break
            deadline += mcu.dt
            while True:
                msg = bus.recv(pace.until_due(deadline))
                if msg is None:
                    break
                _receive(mcu, msg, peers)
            pace.enter(deadline)
            mcu.step()
            if on_step is not None:
                on_step(mcu)
    finally:
        if pace is not clock:
            mcu.clock = owned


def paced(clock: Clock, name: str = "lowerbase emulate") -> PacedClock:
    """``clock`` when it is a :class:`PacedClock` (then paced from now on: a set-up before the
    loop is not a slip), else a new one paced to it (a RealClock or ScaledClock)."""
    if isinstance(clock, PacedClock):
        clock.resync()
        return clock
    return PacedClock(clock, name=name)


@dataclass
class Chassis:
    """One lower computer of a fleet: its MCU, its own bus, its PeerMonitor."""

    mcu: Mcu
    bus: can.BusABC
    peers: PeerMonitor | None = None
    held: list[bytes] | None = None  #: frames written, not yet sent (:func:`send_held`)


def send_held(chassis: Chassis) -> None:
    """Send what ``chassis`` holds, in order; the refused are counted as ``tx_errors``."""
    if chassis.held:
        refused = chassis.bus.send_held(chassis.held)  # type: ignore[attr-defined]
        if refused:
            chassis.mcu.stats["tx_errors"] += refused


def fleet_bus_configs(config: dict[str, Any], n: int) -> list[dict[str, Any]]:
    """The bus of each of ``n`` chassis: udp_multicast ``port + k`` for chassis k (same
    group), python-can's ``virtual`` channel ``CHANNEL/k``; other interfaces have one bus
    per channel the user names, so a fleet cannot share them."""
    if n < 1:
        raise ConfigError(f"a fleet needs at least one chassis, not {n}")
    interface = config.get("interface")
    if interface == "udp_multicast":
        port = int(config.get("port", 43113))
        if port + n - 1 > 65535:
            raise ConfigError(f"--fleet {n} needs ports {port}..{port + n - 1}; choose a lower "
                              "port (--bus-kwargs port=P)")
        return [{**config, "port": port + k} for k in range(n)]
    if interface == "virtual":
        return [{**config, "channel": f"{config.get('channel')}/{k}"} for k in range(n)]
    raise ConfigError(f"a fleet runs on udp_multicast (chassis k on port PORT+k) or virtual, "
                      f"not {interface}")


def fleet_profile(profile: Profile, k: int) -> Profile:
    """Chassis k's profile: the same robot with its own IMU noise and slip seeds (seed + k)."""
    if k == 0:
        return profile
    top = 2**63
    return profile.replace(imu=dataclasses.replace(profile.imu, seed=(profile.imu.seed + k) % top),
                           truth=dataclasses.replace(profile.truth,
                                                     seed=(profile.truth.seed + k) % top))


def run_fleet(
    fleet: Sequence[Chassis], clock: Clock, *, duration: float | None = None,
    stop: threading.Event | None = None, on_step: Callable[[], None] | None = None,
    catalog_filter: bool = True, on_chassis_step: Callable[[int, Chassis], None] | None = None,
    block: int | None = None,
) -> None:
    """Run every chassis until ``duration`` [s] has passed or ``stop`` is set.

    Each period: the frames waiting on any chassis' bus go to that chassis (one ``epoll``
    wait; buses without a file descriptor are polled), every MCU steps (then
    ``on_chassis_step(k, chassis)``) and ``on_step()`` is called; in real time the wait lasts
    until the period's deadline. ``catalog_filter``: as :func:`run`'s. A chassis' frames on
    udp_multicast are held while it steps and sent right after (:func:`send_held`).

    On a :class:`SimClock` without ``on_step`` the fleet runs in blocks of ``block`` periods
    (default: :data:`SIM_BLOCK` from :data:`SIM_BLOCK_FLEET` chassis up, else 1), chassis by
    chassis (:func:`_run_blocks`), so each one's state stays in the CPU's caches for its block
    (docs/emulator.md, "A fleet in one process"): the same frames and state as period by
    period; a bus with a file descriptor is read at the start of each block."""
    if block is None:
        block = SIM_BLOCK if len(fleet) >= SIM_BLOCK_FLEET else 1
    if not fleet:
        return
    if catalog_filter:
        for chassis in fleet:
            listen_to_upper(chassis.bus, chassis.mcu.codec)
    periods = {c.mcu.dt for c in fleet}
    if len(periods) != 1:
        raise ConfigError("a fleet runs on one control period; the profiles' rates.control_hz "
                          f"differ: {sorted(1 / p for p in periods)}")
    dt = fleet[0].mcu.dt
    stop = stop or threading.Event()
    selector = selectors.DefaultSelector()
    polled: list[Chassis] = []
    for chassis in fleet:
        try:
            fd = chassis.bus.fileno()
        except (NotImplementedError, AttributeError):
            fd = -1
        if fd >= 0:
            selector.register(fd, selectors.EVENT_READ, chassis)
        else:
            polled.append(chassis)

    def drain(chassis: Chassis) -> None:
        _drain(chassis.mcu, chassis.bus, chassis.peers)

    def receive(timeout: float) -> None:
        for key, _ in selector.select(timeout):
            drain(key.data)
        for chassis in polled:
            drain(chassis)

    sim = clock if isinstance(clock, SimClock) else None
    pace = None if sim is not None else paced(clock)
    time = sim if sim is not None else pace
    assert time is not None
    owned = [c.mcu.clock for c in fleet]
    if pace is not None:
        for chassis in fleet:
            chassis.mcu.clock = pace
    wait = min(dt / 4, 0.001) if polled else None  # buses without an fd: poll them
    start = deadline = time.now()
    try:
        if sim is not None and on_step is None and block > 1:
            _run_blocks(fleet, sim, selector, drain, duration, stop, on_chassis_step, block)
            return
        while not stop.is_set():
            if duration is not None and time.now() - start >= duration - 1e-9:
                break
            deadline += dt
            if pace is None:
                receive(0.0)
            else:
                while remaining := pace.until_due(deadline):
                    receive(remaining if wait is None else min(remaining, wait))
                receive(0.0)
                pace.enter(deadline)
            for k, chassis in enumerate(fleet):
                chassis.mcu.step()
                send_held(chassis)
                if on_chassis_step is not None:
                    on_chassis_step(k, chassis)
            if sim is not None:
                sim.advance(dt)
            if on_step is not None:
                on_step()
    finally:
        for chassis, mine in zip(fleet, owned, strict=True):
            send_held(chassis)
            if pace is not clock:
                chassis.mcu.clock = mine
        selector.close()


def _run_blocks(
    fleet: Sequence[Chassis], sim: SimClock, selector: selectors.BaseSelector,
    drain: Callable[[Chassis], None], duration: float | None, stop: threading.Event,
    on_chassis_step: Callable[[int, Chassis], None] | None, block: int,
) -> None:
    """run_fleet on the simulated clock, ``block`` periods per chassis at a time, each on a
    clock of its own that advances as the fleet's does (the same floats); then the fleet's
    clock catches up. Buses with a file descriptor are drained at a block's start, buses
    without one before every period."""
    dt = fleet[0].mcu.dt
    has_fd = {id(key.data) for key in selector.get_map().values()}
    done = 0  # periods run
    total = None if duration is None else _periods(sim.now(), duration, dt)
    while not stop.is_set() and (total is None or done < total):
        n = block if total is None else min(block, total - done)
        ready = {id(key.data) for key, _ in selector.select(0.0)}
        t0 = sim.now()
        for k, chassis in enumerate(fleet):
            mcu = chassis.mcu
            own = SimClock(t0)
            mcu.clock = own
            try:
                if id(chassis) in ready:
                    drain(chassis)
                polled = id(chassis) not in has_fd
                if not polled and on_chassis_step is None:
                    mcu.advance(n)  # the same periods, in compiled runs where it can
                    continue
                for _ in range(n):
                    if polled:
                        drain(chassis)
                    mcu.step()
                    if on_chassis_step is not None:  # before the clock moves, as period by period
                        on_chassis_step(k, chassis)
                    own.advance(dt)
            finally:
                mcu.clock = sim
                send_held(chassis)  # the block's frames in one burst of system calls
        for _ in range(n):
            sim.advance(dt)
        done += n


def _periods(start: float, duration: float, dt: float) -> int:
    """How many periods the period-by-period loop runs for ``duration`` from ``start``: it
    stops once the clock has moved ``duration - 1e-9`` (summed the same way: the same count)."""
    t, n = start, 0
    while t - start < duration - 1e-9:
        t += dt
        n += 1
    return n


def open_fleet(
    profile: Profile, clock: Clock, config: dict[str, Any], n: int, *, bms: bool = True,
    soc: float = 80.0, charger: bool = False, faults: Sequence[Any] = (),
) -> list[Chassis]:
    """``n`` chassis, each with its own pack and BMS (unless ``bms`` is False), its own bus
    (:func:`fleet_bus_configs`) and its own seeds (:func:`fleet_profile`). On udp_multicast
    a chassis' frames are held until :func:`send_held` (run_fleet, close_fleet) sends them."""
    from lowerbase.bms.adapter import McuBmsAdapter
    from lowerbase.protocol.codec import default_codec
    from lowerbase.transport import open_bus

    codec = default_codec()
    fleet: list[Chassis] = []

    def make(k: int, bus: can.BusABC) -> Chassis:
        p = fleet_profile(profile, k)
        peers = PeerMonitor(codec)
        chassis = Chassis(None, bus, peers)  # type: ignore[arg-type]  # the MCU just below
        if hasattr(bus, "send_held"):
            chassis.held = []
        send = bus_sender(bus, lambda key: chassis.mcu.stats.update([key]),
                          on_sent=lambda fid, data: peers.on_sent(fid, data,
                                                                 chassis.mcu.clock.now()),
                          sent_ids=(peers.heartbeat_id,), held=chassis.held)
        pack = McuBmsAdapter.from_profile(p, soc=soc, charger=charger) if bms else None
        chassis.mcu = Mcu(p, clock, send, bms=pack, faults=faults, codec=codec)
        return chassis

    try:
        for k, cfg in enumerate(fleet_bus_configs(config, n)):
            bus = open_bus(cfg)
            try:
                fleet.append(make(k, bus))
            except BaseException:
                bus.shutdown()
                raise
    except BaseException:
        close_fleet(fleet)
        raise
    return fleet


def close_fleet(fleet: Sequence[Chassis]) -> None:
    """Shut every chassis down (odometer persisted, BMS closed) and close its bus."""
    for chassis in fleet:
        if chassis.mcu is not None:
            chassis.mcu.shutdown()
            if chassis.mcu.bms is not None:
                chassis.mcu.bms.close()
            send_held(chassis)
        try:
            chassis.bus.shutdown()
        except can.CanError as exc:  # closing must not stop the others from closing
            log.debug("closing a fleet bus: %s", exc)
