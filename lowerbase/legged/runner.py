"""Run a :class:`~lowerbase.legged.lower.LeggedLower` on four python-can buses, one per leg.

The buses of one robot (:func:`leg_bus_configs`): on udp_multicast the same group on ports
PORT..PORT+3 (bus k = leg ``LEGS[k]`` on PORT+k; default PORT 43113); on python-can's
``virtual`` interface channels ``CHANNEL/0``..``CHANNEL/3``; on any other interface (SocketCAN,
an adapter) four channels named with commas, ``-c can0,can1,can2,can3``.

The loop is the wheeled runner's (:mod:`lowerbase.firmware_model.runner`): each 1 ms period the
frames waiting on any bus go to the lower computer (one ``epoll`` wait for the buses that have
a file descriptor, the others polled), then it steps once; in real time the deadline advances
by exactly one period (periodic frames keep their cycle), on a simulated clock the clock jumps
one period. Where the bus filters in the kernel, the lower computer listens only to what the
upper side sends (:func:`lower_listens_to`).
"""

from __future__ import annotations

import contextlib
import logging
import selectors
import threading
from collections.abc import Callable, Sequence
from typing import Any

import can

from lowerbase.clock import Clock, SimClock
from lowerbase.errors import ConfigError
from lowerbase.firmware_model.runner import FULL_ID_MASK, bus_sender, filters_in_kernel, paced
from lowerbase.legged.lower import LeggedLower
from lowerbase.legged.profile import LeggedProfile
from lowerbase.protocol.legged import BODY_BUS, COMMAND_MESSAGES, LEGS, N_BUSES, legged_codec
from lowerbase.transport import is_catalog_frame

log = logging.getLogger(__name__)

DEFAULT_PORT = 43113


def leg_bus_configs(config: dict[str, Any]) -> list[dict[str, Any]]:
    """The four leg buses of one robot from one bus configuration (see the module)."""
    interface = config.get("interface")
    if interface == "udp_multicast":
        port = int(config.get("port", DEFAULT_PORT))
        if port + N_BUSES - 1 > 65535:
            raise ConfigError(f"the legged robot needs ports {port}..{port + N_BUSES - 1}; "
                              "choose a lower port (--bus-kwargs port=P)")
        return [{**config, "port": port + k} for k in range(N_BUSES)]
    channel = config.get("channel")
    if interface == "virtual":
        return [{**config, "channel": f"{channel}/{k}"} for k in range(N_BUSES)]
    names = [c.strip() for c in str(channel or "").split(",") if c.strip()]
    if len(names) != N_BUSES:
        raise ConfigError(f"the legged robot has {N_BUSES} buses ({', '.join(LEGS)}): on "
                          f"{interface} name four channels, e.g. -c can0,can1,can2,can3")
    return [{**config, "channel": name} for name in names]


def lower_listens_to(bus: int) -> list[int]:
    """The IDs the lower computer reads on leg bus ``bus``: the upper side's actuator
    commands (IN_TEST_MODE) everywhere, LocomotionRequest and BodyVelocityCommand on bus 0."""
    codec = legged_codec()
    ids = sorted(COMMAND_MESSAGES)
    if bus != BODY_BUS:
        return ids
    return [*ids, *(codec.message(n).frame_id for n in ("LocomotionRequest",
                                                        "BodyVelocityCommand"))]


def _listen(bus: can.BusABC, k: int) -> None:
    if getattr(bus, "filters", None) or not filters_in_kernel(bus):
        return
    bus.set_filters([{"can_id": i, "can_mask": FULL_ID_MASK} for i in lower_listens_to(k)])


def run_legged(
    lower: LeggedLower, buses: Sequence[can.BusABC], clock: Clock, *,
    duration: float | None = None, stop: threading.Event | None = None,
    on_step: Callable[[LeggedLower], None] | None = None, catalog_filter: bool = True,
) -> None:
    """Run until ``duration`` [s] has passed or ``stop`` is set (see the module)."""
    if len(buses) != N_BUSES:
        raise ConfigError(f"the legged robot runs on {N_BUSES} buses, not {len(buses)}")
    if catalog_filter:
        for k, bus in enumerate(buses):
            _listen(bus, k)
    stop = stop or threading.Event()
    selector = selectors.DefaultSelector()
    polled: list[tuple[int, can.BusABC]] = []
    for k, bus in enumerate(buses):
        try:
            fd = bus.fileno()
        except (NotImplementedError, AttributeError):
            fd = -1
        if fd >= 0:
            selector.register(fd, selectors.EVENT_READ, (k, bus))
        else:
            polled.append((k, bus))

    def drain(k: int, bus: can.BusABC) -> None:
        while (msg := bus.recv(0.0)) is not None:
            if is_catalog_frame(msg):
                lower.receive(k, msg.arbitration_id, bytes(msg.data))
            else:
                lower.stats["rx_frames"] += 1
                lower.stats["rx_not_classic"] += 1

    def receive(timeout: float) -> None:
        for key, _ in selector.select(timeout):
            drain(*key.data)
        for k, bus in polled:
            drain(k, bus)

    sim = clock if isinstance(clock, SimClock) else None
    pace = None if sim is not None else paced(clock, "lowerbase emulate --robot legged")
    time = sim if sim is not None else pace
    assert time is not None
    owned = lower.clock
    if pace is not None:
        lower.clock = pace
    wait = min(lower.dt / 4, 0.001) if polled else None
    start = deadline = time.now()
    try:
        while not stop.is_set():
            if duration is not None and time.now() - start >= duration - 1e-9:
                break
            deadline += lower.dt
            if pace is None:
                receive(0.0)
            else:
                while remaining := pace.until_due(deadline):
                    receive(remaining if wait is None else min(remaining, wait))
                receive(0.0)
                pace.enter(deadline)
            lower.step()
            if sim is not None:
                sim.advance(lower.dt)
            if on_step is not None:
                on_step(lower)
    finally:
        if pace is not clock:
            lower.clock = owned
        selector.close()


def open_legged(
    profile: LeggedProfile, clock: Clock, config: dict[str, Any], *, bms: bool = True,
    soc: float = 80.0, charger: bool = False,
    wrap_send: Callable[[Callable[[int, int, bytes], None]], Callable[[int, int, bytes], None]]
    | None = None, defects: tuple[str, ...] = (),
) -> tuple[LeggedLower, list[can.BusABC]]:
    """The lower computer with its own pack (unless ``bms`` is False) on its four buses
    (:func:`leg_bus_configs`); ``wrap_send`` may wrap its send (e.g. to print frames);
    ``defects``: names of :data:`~lowerbase.legged.lower.DEFECTS`."""
    from lowerbase.transport import open_bus

    if not 0 <= soc <= 100:
        raise ConfigError("--soc must be within 0..100 %")
    configs = leg_bus_configs(config)
    buses: list[can.BusABC] = []
    try:
        for cfg in configs:
            buses.append(open_bus(cfg))
    except BaseException:
        close_buses(buses)
        raise
    stats: list[LeggedLower] = []
    senders = [bus_sender(bus, lambda key: stats[0].stats.update([key])) for bus in buses]

    def send(k: int, frame_id: int, data: bytes) -> None:
        senders[k](frame_id, data)

    lower = LeggedLower(profile, clock, wrap_send(send) if wrap_send else send,
                        bms=legged_bms(profile, soc, charger) if bms else None, defects=defects)
    stats.append(lower)
    return lower, buses


def legged_bms(profile: LeggedProfile, soc: float = 80.0, charger: bool = False) -> Any:
    """The legged pack behind its BMS, as the lower computer polls it (a McuBmsAdapter)."""
    from lowerbase.bms.adapter import McuBmsAdapter
    from lowerbase.bms.device import BmsDevice
    from lowerbase.bms.pack import BatteryPack

    device = BmsDevice(BatteryPack(profile.battery, soc=soc))
    if charger:
        device.connect_charger()
    return McuBmsAdapter(device, low_soc=profile.power.low_battery_soc,
                         critical_soc=profile.power.critical_battery_soc,
                         temp_warning_c=profile.power.battery_temp_warning)


def close_buses(buses: Sequence[can.BusABC]) -> None:
    for bus in buses:
        with contextlib.suppress(can.CanError):
            bus.shutdown()
