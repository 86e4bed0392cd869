"""Every transport carries frames unchanged, in process and between processes."""

from __future__ import annotations

import socket
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import can
import pytest

from lowerbase.errors import TransportError
from lowerbase.transport import DEFAULT_HOP_LIMIT, DEFAULT_INTERFACE, bus_config, open_bus

FRAMES = [(0x020, b"\x01\x02\x03\x04\x05\x06"), (0x100, bytes(range(8))), (0x010, b"\x01"),
          (0x7FF, b"")]


def _msg(frame_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=frame_id, data=data, is_extended_id=False)


def _expect(bus: can.BusABC, frame_id: int) -> can.Message:
    """The next frame with this ID (a multicast bus also hears its own frames)."""
    for _ in range(20):
        got = bus.recv(2.0)
        assert got is not None, f"no frame {frame_id:#x}"
        if got.arbitration_id == frame_id:
            return got
    raise AssertionError(f"no frame {frame_id:#x}")


def _exchange(a: can.BusABC, b: can.BusABC) -> None:
    for frame_id, data in FRAMES:
        a.send(_msg(frame_id, data))
        assert bytes(_expect(b, frame_id).data) == data
        b.send(_msg(frame_id ^ 1, data))
        assert bytes(_expect(a, frame_id ^ 1).data) == data


def test_default_is_udp_multicast_on_this_host_only(monkeypatch: pytest.MonkeyPatch) -> None:
    for var in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(can.util, "CONFIG_FILES", [])
    cfg = bus_config()
    assert cfg["interface"] == DEFAULT_INTERFACE
    assert cfg["hop_limit"] == DEFAULT_HOP_LIMIT == 0
    assert bus_config("virtual", "x")["interface"] == "virtual"


def test_serial_framing_over_a_pty(tmp_path: Path) -> None:
    link = tmp_path / "tty"
    a = open_bus(interface="lowerbase_serial", channel=f"pty:{link}")
    b = open_bus(interface="lowerbase_serial", channel=str(link))
    try:
        assert link.is_symlink()
        _exchange(a, b)
        assert a.deframer.stats.total_errors == 0  # type: ignore[attr-defined]
    finally:
        b.shutdown()
        a.shutdown()
    assert not link.exists()  # the link goes with the pty


def test_slcan_device_speaks_to_python_can_slcan(tmp_path: Path) -> None:
    link = tmp_path / "slcan"
    device = open_bus(interface="slcan_device", channel=f"pty:{link}")
    host = open_bus(interface="slcan", channel=str(link), bitrate=500000, sleep_after_open=0)
    try:
        device.recv(0.2)  # the host's setup commands
        assert device.is_open  # type: ignore[attr-defined]
        _exchange(host, device)
    finally:
        host.shutdown()
        device.shutdown()


def test_udp_multicast_in_process(udp_bus_config: dict[str, Any]) -> None:
    a = open_bus(udp_bus_config)
    b = open_bus(udp_bus_config)
    try:
        _exchange(a, b)
    finally:
        a.shutdown()
        b.shutdown()


ECHO = textwrap.dedent(
    """
    import sys
    import can
    from lowerbase.transport import open_bus
    config = eval(sys.argv[1])
    bus = open_bus(config)
    print("ready", flush=True)
    for _ in range(50):
        msg = bus.recv(10.0)
        if msg is None:
            break
        if msg.arbitration_id & 0x400:
            continue  # our own echo
        bus.send(can.Message(arbitration_id=msg.arbitration_id | 0x400, data=msg.data,
                             is_extended_id=False))
        if msg.arbitration_id == 0x3FF:
            break
    bus.shutdown()
    """
)


def _echo_peer(config: dict[str, Any]) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-c", ECHO, repr(config)], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    return proc


def _ask_peer(bus: can.BusABC, proc: subprocess.Popen[str]) -> None:
    try:
        for frame_id, data in [(0x020, b"\x11\x22"), (0x100, bytes(8)), (0x3FF, b"\x01")]:
            bus.send(_msg(frame_id, data))
            while True:
                got = bus.recv(5.0)
                assert got is not None, "no answer from the other process"
                if got.arbitration_id == frame_id | 0x400:
                    break
            assert bytes(got.data) == data
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()


@pytest.mark.process
def test_two_processes_on_the_default_transport(udp_bus_config: dict[str, Any]) -> None:
    proc = _echo_peer(udp_bus_config)
    bus = open_bus(udp_bus_config)
    try:
        _ask_peer(bus, proc)
    finally:
        bus.shutdown()


@pytest.mark.process
def test_two_processes_over_slcan_on_a_pty(tmp_path: Path) -> None:
    link = tmp_path / "slcan"
    device = open_bus(interface="slcan_device", channel=f"pty:{link}")
    proc = _echo_peer({"interface": "slcan", "channel": str(link), "bitrate": 500000,
                       "sleep_after_open": 0})
    try:
        _ask_peer(device, proc)
    finally:
        device.shutdown()


def _has_af_can() -> bool:
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except (AttributeError, OSError):
        return False
    return True


@pytest.mark.socketcan
@pytest.mark.skipif(not _has_af_can(), reason="the kernel has no SocketCAN (AF_CAN); "
                    "on Linux with vcan: sudo vcan/setup.sh vcan0")
def test_socketcan_vcan0() -> None:
    try:
        a = open_bus(interface="socketcan", channel="vcan0")
    except TransportError as exc:
        pytest.skip(f"vcan0 is not up ({exc}); run: sudo vcan/setup.sh vcan0")
    b = open_bus(interface="socketcan", channel="vcan0")
    try:
        _exchange(a, b)
    finally:
        a.shutdown()
        b.shutdown()


def test_open_errors_are_one_clear_line(tmp_path: Path) -> None:
    with pytest.raises(TransportError, match="unknown CAN interface"):
        open_bus(interface="nosuchbus", channel="x")
    with pytest.raises(TransportError, match="cannot open serial port"):
        open_bus(interface="lowerbase_serial", channel=str(tmp_path / "missing-tty"))
    with pytest.raises(TransportError) as info:
        open_bus(interface="socketcan", channel="nosuchcan0")
    assert "\n" not in str(info.value)
