"""BMS benchmarks: a full discharge on simulated time, and Modbus TCP/RTU request rates.

``run()`` returns :class:`~benchmarks.common.Row` rows; ``python -m benchmarks.bench_bms``
prints them. Network use is loopback (127.0.0.1) and a pseudo-terminal pair only.
"""

from __future__ import annotations

import socket
import time

from benchmarks.common import Row
from lowerbase.transport import free_loopback_port


def bench_full_discharge(load_a: float = 20.0, dt_s: float = 1.0) -> dict:
    """Wall time to discharge a full default pack to the UV cut-off in ``dt_s`` steps."""
    from lowerbase.bms.pack import BatteryPack
    from lowerbase.bms.status import SwitchStatus

    pack = BatteryPack(soc=100.0)
    start = time.perf_counter()
    while pack.switches & SwitchStatus.DISCHARGE:
        pack.step(dt_s, load_a)
        pack.snapshot()  # what a 1 Hz BMS poll costs on top
    wall = time.perf_counter() - start
    return {"name": f"full discharge at {load_a:g} A, dt {dt_s:g} s "
                    f"({pack.time_s / 3600:.2f} h simulated)",
            "value": round(wall, 4), "unit": "s wall"}


def _rate(link: object, seconds: float) -> float:
    n = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        if link.poll() is None:  # type: ignore[attr-defined]
            raise RuntimeError(f"poll failed: {link.last_error}")  # type: ignore[attr-defined]
        n += 1
    return n / (time.perf_counter() - start)


def bench_modbus(seconds: float = 2.0) -> list[dict]:
    """Full-snapshot polls per second (one FC 04 read of every input register)."""
    from lowerbase.bms.device import BmsDevice, BmsServer
    from lowerbase.bms.link import ModbusRtuBmsLink, ModbusTcpBmsLink
    from lowerbase.bms.ptybridge import PtyBridge
    from lowerbase.bms.registers import INPUT_COUNT

    rows = []
    device = BmsDevice()
    with BmsServer(device, tcp=("127.0.0.1", free_loopback_port(socket.SOCK_STREAM))) as server:
        assert server.tcp_address is not None
        with ModbusTcpBmsLink(*server.tcp_address, timeout=1.0) as tcp:
            rows.append({"name": f"Modbus TCP loopback, FC04 x{INPUT_COUNT} registers",
                         "value": round(_rate(tcp, seconds), 1), "unit": "requests/s"})
    with PtyBridge() as bridge:
        server = BmsServer(device, tcp=None, rtu=bridge.a_path)
        with server, ModbusRtuBmsLink(bridge.b_path, timeout=1.0) as rtu:
            rows.append({"name": f"Modbus RTU pty pair, FC04 x{INPUT_COUNT} registers",
                         "value": round(_rate(rtu, seconds), 1), "unit": "requests/s"})
    return rows


def run(quick: bool = False) -> list[Row]:
    """Every BMS benchmark row."""
    rows = [bench_full_discharge(), *bench_modbus(0.5 if quick else 2.0)]
    return [Row("bms", r["name"], float(r["value"]), r["unit"]) for r in rows]


if __name__ == "__main__":
    for row in run():
        print(f"{row.name:<60} {row.value:>10} {row.unit}")
