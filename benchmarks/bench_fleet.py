"""A fleet of emulated chassis in one process: how the cost grows with N, chassis per core.

Each chassis is what ``lowerbase emulate --fleet N`` runs: an MCU with its own pack and BMS,
driving (enabled after boot, a MotionCommand every 20 ms), every frame sent on its own
udp_multicast bus (hop limit 0, port PORT+k), all stepped by ``runner.run_fleet`` on one
simulated clock (from ``SIM_BLOCK_FLEET`` chassis up in blocks of ``SIM_BLOCK`` periods per
chassis, as ``emulate --fleet N --simulated`` runs; the 300-chassis fleet is also run period by
period, block 1, for the comparison). CPU time per simulated second gives the real-time
capacity (the host is shared: wall time also counts other jobs): chassis per core = N / (this
process' CPU seconds per simulated second); the wall figure and the load are noted.
"""

from __future__ import annotations

import os
import time

from benchmarks.common import Row
from lowerbase.clock import SimClock
from lowerbase.firmware_model.mcu import Command
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import (
    SIM_BLOCK,
    Chassis,
    close_fleet,
    open_fleet,
    run_fleet,
)
from lowerbase.transport import free_loopback_port

GROUP = "239.74.163.95"
ENABLE_STEP = 70  #: after the 0.3 s boot


def fleet_cost(n: int, seconds: float, block: int | None = None
               ) -> tuple[float, float, int, int]:
    """(wall and CPU seconds per simulated second, frames sent, frames the bus refused) for
    ``n`` chassis over ``seconds`` of simulated time (after a 0.5 s warm-up: boot, enable).
    CPU is this process's user + system time: on a shared machine it counts only the work.
    ``block``: periods each chassis steps at a time (run_fleet's default; 1: period by
    period)."""
    clock = SimClock()
    config = {"interface": "udp_multicast", "channel": GROUP, "port": free_loopback_port(),
              "hop_limit": 0}
    fleet = open_fleet(load_profile(), clock, config, n)
    steps = [0] * n

    def drive(k: int, chassis: Chassis) -> None:  # after each step of chassis k
        steps[k] += 1
        if steps[k] == ENABLE_STEP:
            chassis.mcu.control(Command.ENABLE_CAN_CONTROL)
        if steps[k] % 4 == 0:
            chassis.mcu.command(0.6, 0.2)

    try:
        run_fleet(fleet, clock, duration=0.5, on_chassis_step=drive, block=block)  # boot
        before = sum(c.mcu.stats["tx_frames"] for c in fleet)
        t0, c0 = time.perf_counter(), time.process_time()
        run_fleet(fleet, clock, duration=seconds, on_chassis_step=drive, block=block)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        sent = sum(c.mcu.stats["tx_frames"] for c in fleet) - before
        refused = sum(c.mcu.stats["tx_errors"] for c in fleet)
    finally:
        close_fleet(fleet)
    return wall / seconds, cpu / seconds, sent - refused, refused


def run(quick: bool = False) -> list[Row]:
    rows = []
    seconds = {1: 20.0, 10: 10.0, 100: 3.0, 300: 2.0} if quick else \
        {1: 60.0, 10: 30.0, 100: 10.0, 300: 10.0}
    for n, sim in seconds.items():
        wall, cpu, sent, refused = fleet_cost(n, sim)
        rows.append(Row("fleet", f"{n} chassis: wall per simulated second", wall * 1e3, "ms",
                        f"{wall * 1e3 / n:.2f} ms per chassis ({n / wall:.0f} per core); CPU "
                        f"{cpu * 1e3:.0f} ms ({n / cpu:.0f} per core); {sent / sim / n:.0f} "
                        f"frames/s each sent, {refused} refused"))
    n = max(seconds)
    wall_n, cpu_n = wall, cpu  # the largest fleet's, in blocks
    wall, cpu, _, _ = fleet_cost(n, seconds[n], block=1)
    rows.append(Row("fleet", f"{n} chassis period by period: wall per simulated second",
                    wall * 1e3, "ms",
                    f"{wall * 1e3 / n:.2f} ms per chassis; CPU {cpu * 1e3:.0f} ms ({n / cpu:.0f} "
                    f"per core); run_fleet block=1 (all chassis each period: their state "
                    f"falls out of the CPU caches), against block={SIM_BLOCK} above"))
    rows.append(Row("fleet", f"chassis per core in real time ({n}-chassis fleet)", n / cpu_n,
                    "chassis",
                    f"target >= 300; by this process' CPU time per simulated second (by wall "
                    f"time {n / wall_n:.0f}; load {os.getloadavg()[0]:.1f}); run_fleet, every "
                    "frame on its chassis' udp_multicast bus"))
    return rows
