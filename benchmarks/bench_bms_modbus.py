"""The BMS's Modbus TCP server against pymodbus' ``ModbusTcpServer``, from outside, over raw
sockets on 127.0.0.1 (docs/bms-modbus.md, "Why not pymodbus' server").

``run()`` returns the numbers (pipelined requests answered, sequential FC 03 requests per
second); ``python -m benchmarks.bench_bms_modbus`` prints them with the behaviour: the answers to
malformed requests and another unit id, and whether an idle connection is closed (the BMS with
a 2 s idle timeout; pymodbus has no such setting, so it is watched for 10 s).

pymodbus serves a fixed datastore of the same shape (input registers 0-18, holding registers
0x0100-0x0120): its rates leave out the BMS model's work (about 60 us per FC 03 request).
"""

from __future__ import annotations

import asyncio
import logging
import select
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from benchmarks.common import Row
from lowerbase.transport import free_loopback_port

READ_OV = bytes.fromhex("03 01 00 00 02")  # FC 03, holding registers 0x0100-0x0101
PIPELINED = 5
#: request PDUs whose answers are compared ("no answer" when none comes within 0.5 s)
ODD_REQUESTS = {
    "FC 0x41 (no such function)": "41",
    "FC 01 read coils": "01 00 00 00 01",
    "FC 2B/0E identification": "2b 0e 01 00",
    "FC 03 address 0x0000 (not a register)": "03 00 00 00 01",
    "FC 03 quantity 0": "03 01 00 00 00",
    "FC 03 quantity 126": "03 01 00 00 7e",
    "FC 03 PDU 2 bytes short": "03 01 00",
}


def _mbap(tid: int, pdu: bytes, unit: int = 1) -> bytes:
    length = (len(pdu) + 1).to_bytes(2, "big")
    return tid.to_bytes(2, "big") + b"\0\0" + length + bytes([unit]) + pdu


def _connect(addr: tuple[str, int]) -> socket.socket:
    s = socket.create_connection(addr, timeout=5.0)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def _frames(s: socket.socket, quiet: float = 0.5) -> list[bytes]:
    """The MBAP frames received until ``quiet`` s pass without a byte (or the peer closes)."""
    buf = b""
    while select.select([s], [], [], quiet)[0]:
        chunk = s.recv(4096)
        if not chunk:
            break
        buf += chunk
    frames = []
    while len(buf) >= 6:
        n = 6 + int.from_bytes(buf[4:6], "big")
        frames, buf = [*frames, buf[:n]], buf[n:]
    return frames


def pipelined(addr: tuple[str, int]) -> int:
    """How many of PIPELINED requests written in one send are answered."""
    with _connect(addr) as s:
        s.sendall(b"".join(_mbap(tid, READ_OV) for tid in range(1, PIPELINED + 1)))
        return len(_frames(s))


def rate(addr: tuple[str, int], n: int) -> float:
    """Sequential FC 03 requests per second on one connection (send, wait for the answer)."""
    requests = [_mbap(i % 65536, READ_OV) for i in range(n)]
    with _connect(addr) as s:
        t0 = time.perf_counter()
        for request in requests:
            s.sendall(request)
            got = b""
            while len(got) < 13:  # MBAP 7 + FC + byte count + 2 registers
                got += s.recv(64)
        return n / (time.perf_counter() - t0)


def behaviour(addr: tuple[str, int], idle_wait: float) -> dict[str, str]:
    out = {}
    for name, pdu in [*ODD_REQUESTS.items(), ("FC 03 to unit id 9 (not ours)", "")]:
        with _connect(addr) as s:
            s.sendall(_mbap(7, bytes.fromhex(pdu)) if pdu else _mbap(7, READ_OV, unit=9))
            out[name] = " ".join(f[7:].hex(" ") for f in _frames(s)) or "no answer"
    with _connect(addr) as s:
        t0 = time.monotonic()
        closed = bool(select.select([s], [], [], idle_wait)[0]) and s.recv(1) == b""
        out["idle connection"] = (f"closed after {time.monotonic() - t0:.1f} s" if closed
                                  else f"open after {idle_wait:g} s")
    return out


@contextmanager
def bms_server(idle_timeout: float | None = 2.0) -> Iterator[tuple[str, int]]:
    from lowerbase.bms.device import BmsDevice, BmsServer
    from lowerbase.bms.pack import BatteryPack

    device = BmsDevice(BatteryPack(soc=72.0), unit=1)
    device.step(20.0, 18.0)
    tcp = ("127.0.0.1", free_loopback_port(socket.SOCK_STREAM))
    with BmsServer(device, tcp=tcp, idle_timeout=idle_timeout) as server:
        assert server.tcp_address is not None
        yield server.tcp_address


@contextmanager
def pymodbus_server() -> Iterator[tuple[str, int]]:
    """pymodbus' ModbusTcpServer on its own event loop thread, unit id 1."""
    from pymodbus.server import ModbusTcpServer
    from pymodbus.simulator import DataType, SimData, SimDevice

    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    addr = ("127.0.0.1", free_loopback_port(socket.SOCK_STREAM))
    started = threading.Event()
    stop: list[Callable[[], None]] = []

    async def main() -> None:
        regs = DataType.REGISTERS
        bit = [SimData(0x9000, values=[False], datatype=DataType.BITS)]  # may not be empty
        device = SimDevice(1, simdata=(bit, list(bit),
                                       [SimData(0x100, values=[3650, 3500] + [0] * 31,
                                                datatype=regs)],
                                       [SimData(0, values=[0] * 19, datatype=regs)]))
        server = ModbusTcpServer(device, address=addr)
        await server.serve_forever(background=True)
        loop = asyncio.get_running_loop()
        stop.append(lambda: asyncio.run_coroutine_threadsafe(server.shutdown(), loop).result(5))
        started.set()
        await server.serving

    thread = threading.Thread(target=asyncio.run, args=(main(),), daemon=True)
    thread.start()
    if not started.wait(5):
        raise RuntimeError("pymodbus' server did not start")
    try:
        yield addr
    finally:
        stop[0]()
        thread.join(5)


def run(quick: bool = False) -> list[Row]:
    import pymodbus

    n = 500 if quick else 2000
    rows = []
    for name, server in (("lowerbase BmsServer", bms_server),
                         (f"pymodbus {pymodbus.__version__} ModbusTcpServer", pymodbus_server)):
        with server() as addr:
            rows.append(Row("bms_modbus", f"{name}: of {PIPELINED} pipelined requests, answered",
                            float(pipelined(addr)), "requests"))
            rows.append(Row("bms_modbus", f"{name}: {n} sequential FC 03 reads",
                            round(rate(addr, n), 1), "requests/s"))
    return rows


if __name__ == "__main__":
    for row in run():
        print(f"{row.name:<70} {row.value:>10} {row.unit}")
    with bms_server() as addr:
        ours = behaviour(addr, 5.0)
    with pymodbus_server() as addr:
        theirs = behaviour(addr, 10.0)
    print(f"\n{'request':<40} {'BmsServer':<22} pymodbus")
    for key, value in ours.items():
        print(f"{key:<40} {value:<22} {theirs[key]}")
