"""The BMS device over Modbus TCP and RTU, read by independent clients (127.0.0.1 only)."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator

import pytest
from pymodbus.client import ModbusTcpClient

from lowerbase.bms.device import BmsDevice, BmsServer, parse_host_port
from lowerbase.bms.link import (
    BmsLink,
    InProcessBmsLink,
    ModbusRtuBmsLink,
    ModbusTcpBmsLink,
)
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.ptybridge import PtyBridge
from lowerbase.bms.registers import (
    HOLDING_BASE,
    HOLDING_COUNT,
    INPUT_COUNT,
    encode_snapshot,
)
from lowerbase.bms.status import BmsStatus
from lowerbase.errors import ConfigError, ModbusDeviceError
from tests.bms import free_port


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    import threading

    yield
    names = {"bms-modbus", "bms-modbus-rtu", "bms-update", "pty-bridge"}
    leaked = [t.name for t in threading.enumerate() if t.name in names]
    assert not leaked, f"threads left running: {leaked}"


@pytest.fixture
def device() -> BmsDevice:
    dev = BmsDevice(BatteryPack(soc=72.0), unit=1)
    dev.step(20.0, 18.0)
    return dev


@pytest.fixture
def tcp_server(device: BmsDevice) -> Iterator[BmsServer]:
    server = BmsServer(device, tcp=("127.0.0.1", free_port()))
    server.start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def client(tcp_server: BmsServer) -> Iterator[ModbusTcpClient]:
    assert tcp_server.tcp_address is not None
    host, port = tcp_server.tcp_address
    c = ModbusTcpClient(host, port=port, timeout=1.0, retries=0)
    assert c.connect()
    try:
        yield c
    finally:
        c.close()


def test_pymodbus_client_reads_the_model(device: BmsDevice, client: ModbusTcpClient) -> None:
    rr = client.read_input_registers(0, count=INPUT_COUNT, device_id=1)
    assert not rr.isError()
    assert rr.registers == encode_snapshot(device.snapshot())
    rr = client.read_holding_registers(HOLDING_BASE, count=HOLDING_COUNT, device_id=1)
    assert rr.registers == device.holding_registers()
    device.step(60.0, 30.0)  # the next read sees the new state
    assert client.read_input_registers(0, count=INPUT_COUNT, device_id=1).registers == (
        encode_snapshot(device.snapshot())
    )


def test_links_agree(device: BmsDevice, tcp_server: BmsServer) -> None:
    assert tcp_server.tcp_address is not None
    with ModbusTcpBmsLink(*tcp_server.tcp_address, timeout=1.0) as tcp:
        links: list[BmsLink] = [InProcessBmsLink(device), tcp]
        assert all(isinstance(link, BmsLink) for link in links)
        first, second = (link.poll() for link in links)
    assert first is not None and first == second


def test_exception_responses(client: ModbusTcpClient) -> None:
    def code(response: object) -> int:
        assert response.isError()  # type: ignore[attr-defined]
        return int(response.exception_code)  # type: ignore[attr-defined]

    assert code(client.read_input_registers(INPUT_COUNT, count=1, device_id=1)) == 0x02
    assert code(client.read_input_registers(0, count=INPUT_COUNT + 1, device_id=1)) == 0x02
    assert code(client.read_holding_registers(0, count=1, device_id=1)) == 0x02
    assert code(client.write_register(0, 1, device_id=1)) == 0x02  # measurements are read-only
    assert code(client.write_register(HOLDING_BASE, 9999, device_id=1)) == 0x03  # out of range
    assert code(client.write_register(HOLDING_BASE, 3400, device_id=1)) == 0x03  # below release
    assert code(client.read_coils(0, count=1, device_id=1)) == 0x01


def test_threshold_write_takes_effect(device: BmsDevice, client: ModbusTcpClient) -> None:
    # cell UV trip/release (registers 0x104/0x105) raised above the present cell voltage
    assert not client.write_registers(HOLDING_BASE + 4, [3330, 3340], device_id=1).isError()
    assert device.pack.config.protection.cell_uv.trip == pytest.approx(3.33)
    rr = client.read_holding_registers(HOLDING_BASE + 4, count=2, device_id=1)
    assert rr.registers == [3330, 3340]
    device.step(3.0, 18.0)
    assert device.snapshot().bms_status & BmsStatus.CELL_UNDER_VOLTAGE
    status = client.read_input_registers(10, count=2, device_id=1).registers
    assert status[1] & BmsStatus.CELL_UNDER_VOLTAGE
    assert client.read_input_registers(15, count=1, device_id=1).registers == [2]  # charge only


def test_other_unit_ids_get_no_answer(tcp_server: BmsServer) -> None:
    assert tcp_server.tcp_address is not None
    with ModbusTcpBmsLink(*tcp_server.tcp_address, unit=2, timeout=0.3) as link:
        assert link.poll() is None and link.last_error


def test_silent_links() -> None:
    link = ModbusTcpBmsLink("127.0.0.1", free_port(), timeout=0.3)
    assert link.poll() is None
    link.close()
    inproc = InProcessBmsLink(BatteryPack())
    inproc.silent = True
    assert inproc.poll() is None


def test_rtu_over_pseudo_terminals(device: BmsDevice) -> None:
    with PtyBridge() as bridge:
        server = BmsServer(device, tcp=None, rtu=bridge.a_path)
        server.start()
        try:
            with ModbusRtuBmsLink(bridge.b_path, timeout=1.0) as link:
                snap = link.poll()
                assert snap is not None and snap == InProcessBmsLink(device).poll()
                assert link.read_holding(HOLDING_BASE, 2) == [3650, 3500]
        finally:
            server.stop()


def test_pty_symlink(tmp_path: object) -> None:
    from pathlib import Path

    link = Path(str(tmp_path)) / "bms"
    with PtyBridge(link) as bridge:
        assert link.is_symlink() and str(link.resolve()) == bridge.b_path
    assert not link.exists() and not link.is_symlink()
    link.write_text("not a link")
    with pytest.raises(Exception, match="not a symlink"):
        PtyBridge(link)


MBPOLL_MISSING = "mbpoll not on PATH (Debian: apt-get install -y mbpoll)"


@pytest.mark.skipif(shutil.which("mbpoll") is None, reason=MBPOLL_MISSING)
def test_mbpoll_reads_and_is_refused(device: BmsDevice, tcp_server: BmsServer) -> None:
    assert tcp_server.tcp_address is not None
    port = str(tcp_server.tcp_address[1])
    base = ["mbpoll", "-m", "tcp", "-p", port, "-a", "1", "-0", "-1", "-o", "1"]
    out = subprocess.run(
        [*base, "-t", "3", "-r", "0", "-c", str(INPUT_COUNT), "127.0.0.1"],
        capture_output=True, text=True, timeout=10, check=True,
    ).stdout
    values = {}
    for line in out.splitlines():
        if line.startswith("["):
            idx, _, val = line.partition(":")
            values[int(idx.strip("[]"))] = int(val.split()[0])
    expected = encode_snapshot(device.snapshot())
    assert [values[i] for i in range(INPUT_COUNT)] == expected
    bad = subprocess.run(
        [*base, "-t", "4", "-r", str(HOLDING_BASE), "127.0.0.1", "9999"],
        capture_output=True, text=True, timeout=10,
    )
    assert bad.returncode != 0 and "Illegal data value" in bad.stdout + bad.stderr
    bad = subprocess.run(
        [*base, "-t", "3", "-r", "500", "127.0.0.1"], capture_output=True, text=True, timeout=10
    )
    assert bad.returncode != 0 and "Illegal data address" in bad.stdout + bad.stderr


def test_port_in_use_is_one_clear_error(tcp_server: BmsServer) -> None:
    assert tcp_server.tcp_address is not None
    other = BmsServer(BmsDevice(), tcp=tcp_server.tcp_address)
    with pytest.raises(ModbusDeviceError, match=r"cannot listen on Modbus TCP 127\.0\.0\.1"):
        other.start()
    with pytest.raises(ModbusDeviceError, match="cannot open serial port"):
        BmsServer(BmsDevice(), tcp=None, rtu="/nonexistent/tty").start()


def test_stop_frees_the_port(device: BmsDevice) -> None:
    addr = ("127.0.0.1", free_port())
    for _ in range(2):
        server = BmsServer(device, tcp=addr)
        server.start()
        server.stop()
        server.stop()  # idempotent


def test_update_loop_on_a_simulated_clock(device: BmsDevice) -> None:
    import threading

    from lowerbase.clock import SimClock

    clock = SimClock()
    stop = threading.Event()
    before = device.pack.time_s

    class Limited(SimClock):
        def sleep_until(self, deadline: float) -> None:
            super().sleep_until(deadline)
            if self.now() >= 600.0:
                stop.set()

    device.run(Limited(), stop, period=0.5, speed=2.0)
    assert device.pack.time_s - before == pytest.approx(1200.0)
    assert clock.now() == 0.0


@pytest.mark.parametrize(
    ("text", "expected"),
    [("127.0.0.1:5020", ("127.0.0.1", 5020)), (":1502", ("127.0.0.1", 1502)),
     ("localhost", ("localhost", 5020)), ("[::1]:503", ("::1", 503))],
)
def test_parse_host_port(text: str, expected: tuple[str, int]) -> None:
    assert parse_host_port(text) == expected


@pytest.mark.parametrize("text", ["host:port", "127.0.0.1:70000"])
def test_parse_host_port_errors(text: str) -> None:
    with pytest.raises(ConfigError):
        parse_host_port(text)
