"""The BMS's Modbus TCP server byte for byte, from outside, over raw sockets on 127.0.0.1.

Transcripts are hex: MBAP header (transaction id, protocol 0, length, unit id), then the PDU.
The device's thresholds are the LFP defaults: cell OV trip 3.650 V (0x0e42), release 3.500 V
(0x0dac).
"""

from __future__ import annotations

import select
import socket
from collections.abc import Iterator

import pytest
from pymodbus.client import ModbusTcpClient

from lowerbase.bms.device import BmsDevice, BmsServer
from lowerbase.bms.pack import BatteryPack
from tests.bms import free_port


def h(text: str) -> bytes:
    return bytes.fromhex(text)


@pytest.fixture
def server() -> Iterator[BmsServer]:
    device = BmsDevice(BatteryPack(soc=72.0), unit=1)
    device.step(20.0, 18.0)
    srv = BmsServer(device, tcp=("127.0.0.1", free_port()))
    srv.start()
    try:
        yield srv
    finally:
        srv.stop()


@pytest.fixture
def sock(server: BmsServer) -> Iterator[socket.socket]:
    assert server.tcp_address is not None
    s = socket.create_connection(server.tcp_address, timeout=5.0)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    try:
        yield s
    finally:
        s.close()


def recv_exactly(s: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = s.recv(n - len(data))
        if not chunk:
            break
        data += chunk
    return data


def nothing_pending(s: socket.socket, wait: float = 0.2) -> bool:
    """True when no byte arrives within ``wait`` s (used only for "no answer" checks)."""
    ready, _, _ = select.select([s], [], [], wait)
    return not ready


def exchange(s: socket.socket, request: str, expected: str) -> None:
    s.sendall(h(request))
    assert recv_exactly(s, len(h(expected))).hex(" ") == expected


# a read the device answers, and its answer: holding registers 0x0100-0x0101 (cell OV)
READ_OV = "01 03 01 00 00 02"
OV_ANSWER = "01 03 04 0e 42 0d ac"


@pytest.mark.parametrize(
    ("request_pdu", "answer_pdu"),
    [
        ("03 01 00 00 00", "83 03"),  # FC03 quantity 0
        ("03 01 00 00 7e", "83 03"),  # FC03 quantity 126 > 125
        ("04 00 00 00 00", "84 03"),  # FC04 quantity 0
        ("04 00 00 00 7e", "84 03"),  # FC04 quantity 126
        ("03 01 00", "83 03"),  # short PDU
        ("04 00 00 00 01 00", "84 03"),  # PDU one byte too long
        ("06 01 00", "86 03"),  # short write
        ("10 01 00 00 7c f8 0e 42", "90 03"),  # FC16 quantity 124 > 123
        ("10 01 00 00 00 00", "90 03"),  # FC16 quantity 0
        ("10 01 00 00 01 04 0e 42", "90 03"),  # byte count 4 for 1 register
        ("10 01 00 00 02 04 0e 42", "90 03"),  # byte count 4, 2 bytes follow
        ("17 01 00 00 00 01 00 00 01 02 0e 42", "97 03"),  # FC23 read quantity 0
        ("17 01 00 00 01 01 00 00 7a f4 0e 42", "97 03"),  # FC23 write 122 > 121
        ("03 00 00 00 01", "83 02"),  # holding register 0 does not exist
        ("04 00 13 00 01", "84 02"),  # past the input table
        ("17 00 00 00 01 01 00 00 01 02 0e 42", "97 02"),  # FC23 read outside the table
        ("06 01 00 0e 10", "86 03"),  # OV trip 3.600 V: not above the charger's CV voltage
        ("01 00 00 00 01", "81 01"),  # no coils
        ("02 00 00 00 01", "82 01"),  # no discrete inputs
        ("05 00 00 ff 00", "85 01"),
        ("07", "87 01"),  # read exception status
        ("08 00 00 12 34", "88 01"),  # diagnostics (echo)
        ("0b", "8b 01"),  # comm event counter
        ("11", "91 01"),  # report server id: would name the software
        ("14 07 06 00 04 00 00 00 02", "94 01"),  # read file record
        ("2b 0e 01 00", "ab 01"),  # read device identification: would name the software
        ("41 00", "c1 01"),
    ],
)
def test_refused_requests_get_standard_exceptions(
    sock: socket.socket, request_pdu: str, answer_pdu: str
) -> None:
    exchange(
        sock, f"12 34 00 00 00 {len(h(request_pdu)) + 1:02x} 01 {request_pdu}",
        f"12 34 00 00 00 {len(h(answer_pdu)) + 1:02x} 01 {answer_pdu}",
    )
    exchange(sock, f"00 02 00 00 00 06 {READ_OV}", f"00 02 00 00 00 07 {OV_ANSWER}")


def test_answers(server: BmsServer, sock: socket.socket) -> None:
    exchange(sock, f"00 01 00 00 00 06 {READ_OV}", f"00 01 00 00 00 07 {OV_ANSWER}")
    # FC06 and FC16 echo address and value / quantity; FC23 writes, then reads
    exchange(sock, "00 02 00 00 00 06 01 06 01 00 0e 74", "00 02 00 00 00 06 01 06 01 00 0e 74")
    exchange(sock, "00 03 00 00 00 09 01 10 01 01 00 01 02 0d 48",
             "00 03 00 00 00 06 01 10 01 01 00 01")
    exchange(sock, "00 04 00 00 00 0d 01 17 01 00 00 02 01 00 00 01 02 0e 88",
             "00 04 00 00 00 07 01 17 04 0e 88 0d 48")
    assert server.device.holding_registers()[:2] == [0x0E88, 0x0D48]


def test_pipelined_requests_are_all_answered_in_order(sock: socket.socket) -> None:
    requests = [
        f"00 0a 00 00 00 06 {READ_OV}",
        "00 0b 00 00 00 02 01 07",  # refused
        "00 0c 00 00 00 06 01 06 01 01 0d 48",  # OV release 3.400 V
        "00 0d 00 00 00 06 01 03 01 01 00 01",
        "00 0e 00 00 00 06 02 03 01 00 00 01",  # another unit id: no answer
        "00 0f 00 00 00 06 01 04 00 11 00 01",
    ]
    answers = [
        f"00 0a 00 00 00 07 {OV_ANSWER}",
        "00 0b 00 00 00 03 01 87 01",
        "00 0c 00 00 00 06 01 06 01 01 0d 48",
        "00 0d 00 00 00 05 01 03 02 0d 48",
        "00 0f 00 00 00 05 01 04 02 00 00",  # charge_mode: no charger
    ]
    sock.sendall(b"".join(h(r) for r in requests))  # one segment
    expected = b"".join(h(a) for a in answers)
    assert recv_exactly(sock, len(expected)).hex(" ") == expected.hex(" ")
    assert nothing_pending(sock)


def test_a_request_split_over_segments(sock: socket.socket) -> None:
    whole = h(f"00 21 00 00 00 06 {READ_OV}" + f" 00 22 00 00 00 06 {READ_OV}")
    for cut in (3, 9, 14):  # inside the MBAP header, inside the PDU, inside the 2nd request
        sock.sendall(whole[:cut])
        if cut < 12:
            assert nothing_pending(sock, 0.05)  # no answer to half a request
        sock.sendall(whole[cut:])
        expected = h(f"00 21 00 00 00 07 {OV_ANSWER} 00 22 00 00 00 07 {OV_ANSWER}")
        assert recv_exactly(sock, len(expected)) == expected


def test_unanswered_frames_keep_the_stream_in_step(server: BmsServer, sock: socket.socket) -> None:
    sock.sendall(h("00 01 00 05 00 06 01 03 01 00 00 02"))  # protocol id 5: not Modbus
    sock.sendall(h("00 02 00 00 00 06 07 03 01 00 00 02"))  # unit 7
    sock.sendall(h("00 03 00 00 00 01 01"))  # unit id and no function code
    exchange(sock, f"00 04 00 00 00 06 {READ_OV}", f"00 04 00 00 00 07 {OV_ANSWER}")
    assert server.dropped["other unit id"] == 1 and server.dropped["empty PDU"] == 1
    assert server.dropped["frame with a protocol id other than 0"] == 1


@pytest.mark.parametrize("fc", ["00", "80", "83", "ff"])
def test_invalid_function_codes_are_dropped_not_answered(
        server: BmsServer, sock: socket.socket, fc: str) -> None:
    """0 is no function code, 0x80-0xFF mark exception responses (Modbus Application Protocol
    6.0 / 7): an answer `80 01` or `FF 01` would look like an exception frame itself."""
    sock.sendall(h(f"00 01 00 00 00 06 01 {fc} 01 00 00 02"))
    exchange(sock, f"00 02 00 00 00 06 {READ_OV}", f"00 02 00 00 00 07 {OV_ANSWER}")
    assert server.dropped["invalid function code"] == 1


def test_broadcast_writes_without_answering(server: BmsServer, sock: socket.socket) -> None:
    sock.sendall(h("00 01 00 00 00 06 00 06 01 00 0e 74"))
    exchange(sock, f"00 02 00 00 00 06 {READ_OV}", "00 02 00 00 00 07 01 03 04 0e 74 0d ac")


def test_a_bad_length_closes_the_connection(server: BmsServer, sock: socket.socket) -> None:
    sock.sendall(h("00 01 00 00 01 00 01 03"))  # length 256: no Modbus frame is that long
    assert closed_by_peer(sock)
    assert server.dropped["connection with a bad MBAP length"] == 1


def closed_by_peer(s: socket.socket) -> bool:
    """Wait (bounded by the socket's timeout) until the server closes the connection."""
    try:
        return s.recv(16) == b""
    except ConnectionResetError:
        return True


def test_idle_connections_are_closed() -> None:
    device = BmsDevice(BatteryPack(soc=72.0))
    with BmsServer(device, tcp=("127.0.0.1", 0), idle_timeout=1.0) as server:
        assert server.tcp_address is not None
        with socket.create_connection(server.tcp_address, timeout=10.0) as s:
            exchange(s, f"00 01 00 00 00 06 {READ_OV}", f"00 01 00 00 00 07 {OV_ANSWER}")
            s.sendall(h("00 02 00 00"))  # then half a request, and silence
            assert closed_by_peer(s)
        assert server.dropped["idle connection"] == 1
        with socket.create_connection(server.tcp_address, timeout=10.0) as s:
            assert closed_by_peer(s)  # a connection that never sends anything, too
        assert server.dropped["idle connection"] == 2


def test_pymodbus_client_sees_no_identification(sock: socket.socket, server: BmsServer) -> None:
    assert server.tcp_address is not None
    host, port = server.tcp_address
    client = ModbusTcpClient(host, port=port, timeout=2.0, retries=0)
    assert client.connect()
    try:
        info = client.read_device_information(device_id=1)
        assert info.isError() and info.exception_code == 0x01
        rr = client.report_device_id(device_id=1)
        assert rr.isError() and rr.exception_code == 0x01
        assert client.diag_read_bus_message_count(device_id=1).isError()
    finally:
        client.close()


def test_a_failing_model_is_a_device_failure(caplog: pytest.LogCaptureFixture) -> None:
    from lowerbase.bms.modbus import handle_pdu

    class Broken(BmsDevice):
        def input_registers(self) -> list[int]:
            raise ZeroDivisionError("model bug")

    with caplog.at_level("ERROR", logger="lowerbase.bms.modbus"):
        assert handle_pdu(Broken(), h("04 00 00 00 01")) == h("84 04")
    assert "BMS device failure on request 04 00 00 00 01" in caplog.text


def test_garbage_connections_are_counted_and_logged_rate_limited(
        server: BmsServer, caplog: pytest.LogCaptureFixture) -> None:
    """Each garbage connection is counted; only the first few of a kind and then every 100th
    are logged, with the count so far (a port scan does not flood the log)."""
    assert server.tcp_address is not None
    with caplog.at_level("INFO", logger="lowerbase.bms.modbus"):
        for _ in range(30):
            with socket.create_connection(server.tcp_address, timeout=5.0) as s:
                s.sendall(h("00 01 00 00 01 00 01 03"))  # length 256: garbage
                assert closed_by_peer(s)  # the drop is counted (and logged) before the close
    assert server.dropped["connection with a bad MBAP length"] == 30
    lines = [r.getMessage() for r in caplog.records if "bad MBAP length" in r.getMessage()]
    assert len(lines) == 5, lines
    assert "(5 so far; further ones are logged every 100th)" in lines[-1]


def test_drop_logs_the_first_five_then_every_hundredth(caplog: pytest.LogCaptureFixture) -> None:
    from lowerbase.bms.modbus import SlaveCore

    core = SlaveCore(BmsDevice(BatteryPack(soc=72.0), unit=1))
    with caplog.at_level("INFO", logger="lowerbase.bms.modbus"):
        for _ in range(1000):
            core.drop("idle connection", "127.0.0.1:1")
        core.drop("empty PDU")  # counted per kind
    assert core.dropped["idle connection"] == 1000 and core.dropped["empty PDU"] == 1
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 5 + 10 + 1
    assert lines[0] == "Modbus: dropped idle connection (127.0.0.1:1)"
    assert lines[14] == "Modbus: dropped idle connection (127.0.0.1:1) (1000 so far; further " \
                        "ones are logged every 100th)"
    assert lines[15] == "Modbus: dropped empty PDU"
