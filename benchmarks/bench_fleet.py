"""A fleet of emulated chassis in one process: how the cost grows with N, chassis per core.

What ``lowerbase emulate --fleet N --simulated`` runs, driven as a user drives it: each chassis
is an MCU with its own pack and BMS on its own udp_multicast bus (hop limit 0, port PORT+k);
its upper side enables it after boot and then sends a MotionCommand every 20 ms of simulated
time over that bus (python-can's wire format, from this process: a block's 10 commands before
each 0.2 s slice, which the chassis reads at the slice's start, as run_fleet reads a bus).
``runner.run_fleet`` runs the fleet on its normal path (no per-step hook: in blocks of
``SIM_BLOCK`` periods per chassis, in compiled runs where they apply; the 300-chassis fleet is
also run period by period, block 1, where every period is a Python step). CPU time per simulated
second gives the real-time capacity (the host is shared: wall time also counts other jobs):
chassis per core = N / (this process' CPU seconds per simulated second, the upper sides'
sending excluded: in use they are other processes); the wall figure and the load are noted.
"""

from __future__ import annotations

import os
import socket
import time

from benchmarks.common import Row
from lowerbase.clock import SimClock
from lowerbase.errors import TransportError
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import (
    SIM_BLOCK,
    close_fleet,
    open_fleet,
    run_fleet,
)
from lowerbase.protocol.codec import default_codec
from lowerbase.transport import free_loopback_port
from lowerbase.transport.udp_wire import pack_classic

GROUP = "239.74.163.95"
SLICE = SIM_BLOCK  #: periods between the upper sides' bursts (0.2 s, one block)
COMMANDS = SLICE // 4  #: MotionCommands per slice: 50 Hz at the 200 Hz control rate


class Uppers:
    """The upper side of every chassis: one loopback socket sending python-can datagrams to
    chassis k's port (PORT+k); enable once, then MotionCommands with a running counter."""

    def __init__(self, port: int, n: int) -> None:
        codec = default_codec()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                             socket.inet_aton("127.0.0.1"))
        self.dests = [(GROUP, port + k) for k in range(n)]
        control = codec.message("ControlCommand")
        self.enable = pack_classic(control.frame_id,
                                   control.encode({"Command": "EnableCanControl"}))
        motion = codec.message("MotionCommand")
        self.motion = [pack_classic(motion.frame_id, motion.encode(
            {"Linear": 0.6, "Angular": 0.2, "Mode": "Raw", "Counter": c})) for c in range(16)]
        self.counter = 0
        self.cpu = 0.0  #: CPU seconds spent sending

    def send(self, enable: bool = False) -> None:
        c0 = time.process_time()
        burst = [self.enable] if enable else [
            self.motion[(self.counter + i) & 0xF] for i in range(COMMANDS)]
        self.counter += 0 if enable else COMMANDS
        for dest in self.dests:
            for datagram in burst:
                self.sock.sendto(datagram, dest)
        self.cpu += time.process_time() - c0


def fleet_cost(n: int, seconds: float, block: int | None = None
               ) -> tuple[float, float, int, int, int]:
    """(wall and CPU seconds per simulated second, frames sent, frames the bus refused,
    commands received) for ``n`` chassis over ``seconds`` of simulated time (after a 0.6 s
    warm-up: boot, enable). CPU is this process's user + system time less the upper sides'
    sending: on a shared machine it counts only the work. ``block``: periods each chassis
    steps at a time (run_fleet's default; 1: period by period)."""
    clock = SimClock()
    for attempt in range(5):  # a port of the range PORT..PORT+n-1 may be taken meanwhile
        port = free_loopback_port()
        config = {"interface": "udp_multicast", "channel": GROUP, "port": port, "hop_limit": 0}
        try:
            fleet = open_fleet(load_profile(), clock, config, n)
            break
        except TransportError:
            if attempt == 4:
                raise
    uppers = Uppers(port, n)
    dt = fleet[0].mcu.dt

    def drive(slices: int, first: bool = False) -> None:
        for i in range(slices):
            uppers.send()
            run_fleet(fleet, clock, duration=SLICE * dt, block=block,
                      catalog_filter=first and i == 0)

    try:
        run_fleet(fleet, clock, duration=0.4, block=block)  # boot (0.3 s)
        uppers.send(enable=True)
        drive(1, first=True)
        before = sum(c.mcu.stats["tx_frames"] for c in fleet)
        rx = sum(c.mcu.stats["rx_frames"] for c in fleet)
        uppers.cpu = 0.0
        t0, c0 = time.perf_counter(), time.process_time()
        drive(round(seconds / (SLICE * dt)))
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0 - uppers.cpu
        sent = sum(c.mcu.stats["tx_frames"] for c in fleet) - before
        received = sum(c.mcu.stats["rx_frames"] for c in fleet) - rx
        refused = sum(c.mcu.stats["tx_errors"] for c in fleet)
    finally:
        close_fleet(fleet)
        uppers.sock.close()
    return wall / seconds, cpu / seconds, sent - refused, refused, received


def run(quick: bool = False) -> list[Row]:
    rows = []
    seconds = {1: 20.0, 10: 10.0, 100: 3.0, 300: 2.0} if quick else \
        {1: 60.0, 10: 30.0, 100: 10.0, 300: 10.0}
    for n, sim in seconds.items():
        wall, cpu, sent, refused, received = fleet_cost(n, sim)
        rows.append(Row("fleet", f"{n} chassis: wall per simulated second", wall * 1e3, "ms",
                        f"{wall * 1e3 / n:.2f} ms per chassis ({n / wall:.0f} per core); CPU "
                        f"{cpu * 1e3:.0f} ms ({n / cpu:.0f} per core); {sent / sim / n:.0f} "
                        f"frames/s each sent, {refused} refused, {received / sim / n:.0f} "
                        "commands/s each received"))
    n = max(seconds)
    wall_n, cpu_n = wall, cpu  # the largest fleet's, in blocks
    wall, cpu, _, _, _ = fleet_cost(n, seconds[n], block=1)
    rows.append(Row("fleet", f"{n} chassis period by period: wall per simulated second",
                    wall * 1e3, "ms",
                    f"{wall * 1e3 / n:.2f} ms per chassis; CPU {cpu * 1e3:.0f} ms ({n / cpu:.0f} "
                    f"per core); run_fleet block=1 (all chassis each period, each a Python "
                    f"step), against block={SIM_BLOCK} above"))
    rows.append(Row("fleet", f"chassis per core in real time ({n}-chassis fleet)", n / cpu_n,
                    "chassis",
                    f"target >= 300; by this process' CPU time per simulated second (by wall "
                    f"time {n / wall_n:.0f}; load {os.getloadavg()[0]:.1f}); run_fleet, every "
                    "frame on its chassis' udp_multicast bus, commands received over it"))
    return rows
