"""BusLink survives its device going away and coming back (a pty that vanishes, a bus that
fails), reports the link down at once and reopens every reopen_period: no respawn."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import can
import pytest

from lowerbase.cli.driver import bus_link
from lowerbase.clock import SimClock
from lowerbase.driver.links import BusLink, missing_device
from lowerbase.errors import TransportError
from lowerbase.transport.serial_bus import SerialFrameBus


class Recorder:
    def __init__(self) -> None:
        self.frames: list[tuple[int, bytes]] = []
        self.downs: list[str] = []

    def frame(self, frame_id: int, data: bytes) -> None:
        self.frames.append((frame_id, data))

    def down(self, why: str) -> None:
        self.downs.append(why)


def test_serial_device_vanishes_and_comes_back(tmp_path: Path) -> None:
    tty = tmp_path / "chassis-tty"
    emulator = SerialFrameBus(f"pty:{tty}")
    clock = SimClock()
    link = BusLink({"interface": "lowerbase_serial", "channel": str(tty)}, clock=clock)
    rec = Recorder()
    emulator.send(can.Message(arbitration_id=0x90, data=b"\x01" * 8, is_extended_id=False))
    assert link.poll(rec.frame, rec.down, timeout=2.0) == 0.0
    assert rec.frames == [(0x90, b"\x01" * 8)]
    emulator.shutdown()  # the emulator is killed: the pty and its link are gone
    for _ in range(20):  # the slave reports the hang-up as an error (not as silence)
        if link.poll(rec.frame, rec.down, timeout=0.5) > 0:
            break
    assert len(rec.downs) == 1 and "receive failed" in rec.downs[0]
    assert not link.is_open and link.rx_errors == 1
    link.send(0x20, b"\0" * 6)  # what the driver sends meanwhile is counted, not raised
    assert link.tx_errors == 1
    clock.advance(1.0)
    assert link.poll(rec.frame, rec.down) == 1.0  # nothing to open yet: retry in 1 s
    assert link.poll(rec.frame, rec.down) == pytest.approx(1.0)  # not before it is due
    emulator = SerialFrameBus(f"pty:{tty}")  # started again at the same path
    try:
        clock.advance(1.0)
        assert link.poll(rec.frame, rec.down) == 0.0 and link.is_open and link.reopens == 1
        emulator.send(can.Message(arbitration_id=0x90, data=b"\x02" * 8, is_extended_id=False))
        assert link.poll(rec.frame, rec.down, timeout=2.0) == 0.0
        assert rec.frames[-1] == (0x90, b"\x02" * 8)
        assert len(rec.downs) == 1
    finally:
        emulator.shutdown()
        link.close()


class FlakyBus:
    """A bus whose receive or transmit fails on demand (an adapter unplugged)."""

    def __init__(self) -> None:
        self.fail_recv = False
        self.fail_send = False
        self.closed = False

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.fail_recv:
            raise can.CanOperationError("device gone")
        return can.Message(arbitration_id=0x90, data=b"\0" * 8, is_extended_id=False)

    def send(self, msg: can.Message) -> None:
        if self.fail_send:
            raise OSError(19, "No such device")

    def shutdown(self) -> None:
        self.closed = True


def test_any_error_closes_and_reopens_on_the_period() -> None:
    clock = SimClock()
    buses: list[FlakyBus] = []
    plugged = [True]

    def opener(config: dict[str, Any]) -> FlakyBus:
        if not plugged[0]:
            raise TransportError("cannot open socketcan channel 'can0': No such device")
        buses.append(FlakyBus())
        return buses[-1]

    link = BusLink({"interface": "socketcan", "channel": "can0"}, reopen_period=1.0,
                   opener=opener, clock=clock)
    rec = Recorder()
    link.poll(rec.frame, rec.down)
    assert len(rec.frames) == 1
    buses[0].fail_send = True  # a transmit error: the reader closes and reopens the bus
    link.send(0x20, b"\0" * 6)
    plugged[0] = False
    assert link.poll(rec.frame, rec.down) == 1.0
    assert buses[0].closed and rec.downs == ["transmit failed: [Errno 19] No such device"]
    attempts = 0
    for _ in range(5):  # unplugged for 5 s: one attempt per second
        clock.advance(1.0)
        link.poll(rec.frame, rec.down)
        attempts += 1
    assert len(buses) == 1 and attempts == 5
    plugged[0] = True
    clock.advance(1.0)
    assert link.poll(rec.frame, rec.down) == 0.0 and len(buses) == 2
    link.poll(rec.frame, rec.down)
    assert len(rec.frames) == 2
    buses[1].fail_recv = True  # a receive error: the same
    link.poll(rec.frame, rec.down)
    assert len(rec.downs) == 2 and buses[1].closed
    clock.advance(1.0)
    link.poll(rec.frame, rec.down)
    assert len(buses) == 3 and link.reopens == 2


def test_the_first_open_failure_is_the_users(tmp_path: Path) -> None:
    """A device that is there but does not open (not a tty, no permission) is an error at
    start; only a device that does not exist yet is waited for."""
    there = tmp_path / "ttyUSB9"
    there.write_text("")

    def opener(config: dict[str, Any]) -> Any:
        raise TransportError(f"cannot open serial port {there}: not a tty")

    with pytest.raises(TransportError, match="ttyUSB9"):
        BusLink({"interface": "lowerbase_serial", "channel": str(there)}, opener=opener)
    with pytest.raises(TransportError, match="ttyUSB9"):
        BusLink({"interface": "socketcan", "channel": "can0"}, opener=opener)


def test_a_serial_device_that_is_not_there_yet_is_waited_for(tmp_path: Path) -> None:
    """The emulator started second (or the adapter plugged in later): the link says once that
    it waits, looks for the device every reopen_period and opens it when it appears."""
    tty = tmp_path / "chassis-tty"
    clock = SimClock()
    lines: list[str] = []
    link = BusLink({"interface": "lowerbase_serial", "channel": str(tty)}, clock=clock,
                   announce=lines.append)
    rec = Recorder()
    try:
        assert not link.is_open
        assert len(lines) == 1 and f"waiting for {tty}" in lines[0], lines
        for _ in range(3):  # missing for 3 s: one look a second, nothing more said
            assert link.poll(rec.frame, rec.down) == pytest.approx(1.0)
            assert link.poll(rec.frame, rec.down) == pytest.approx(1.0)  # not before due
            clock.advance(1.0)
        assert len(lines) == 1 and rec.downs == [] and link.reopens == 0
        link.send(0x20, b"\0" * 6)  # what the driver sends meanwhile is counted, not raised
        assert link.tx_errors == 1
        emulator = SerialFrameBus(f"pty:{tty}")  # the emulator publishes its pty there
        try:
            assert link.poll(rec.frame, rec.down) == 0.0 and link.is_open
            assert len(lines) == 2 and str(tty) in lines[1] and "open" in lines[1], lines
            emulator.send(can.Message(arbitration_id=0x90, data=b"\x03" * 8,
                                      is_extended_id=False))
            for _ in range(20):  # a generous bound: the frame is there at the first receive
                link.poll(rec.frame, rec.down, timeout=0.5)
                if rec.frames:
                    break
            assert rec.frames == [(0x90, b"\x03" * 8)] and link.reopens == 0
        finally:
            emulator.shutdown()
    finally:
        link.close()


def test_missing_device_names_only_serial_device_files(tmp_path: Path) -> None:
    there = tmp_path / "ttyACM0"
    there.write_text("")
    gone = tmp_path / "ttyACM1"
    assert missing_device({"interface": "lowerbase_serial", "channel": str(gone)}) == str(gone)
    assert missing_device({"interface": "slcan", "channel": f"{gone}@115200"}) == str(gone)
    assert missing_device({"interface": "lowerbase_serial", "channel": str(there)}) is None
    assert missing_device({"interface": "lowerbase_serial", "channel": f"pty:{gone}"}) is None
    assert missing_device({"interface": "lowerbase_serial", "channel": "loop://"}) is None
    assert missing_device({"interface": "socketcan", "channel": "can0"}) is None
    assert missing_device({"interface": "udp_multicast", "channel": "239.74.163.2"}) is None
    (tmp_path / "dangling").symlink_to(gone)  # an emulator's old pty link: not there
    assert missing_device({"interface": "lowerbase_serial",
                           "channel": str(tmp_path / "dangling")}) == str(tmp_path / "dangling")



def test_the_driver_command_says_once_that_it_waits(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """`lowerbase driver --serial PATH` with PATH not there yet: one line, no exit."""
    tty = tmp_path / "chassis-tty"
    link = bus_link({"interface": "lowerbase_serial", "channel": str(tty), "baudrate": 115200})
    try:
        assert not link.is_open
        out = capsys.readouterr().out.splitlines()
        assert out == [f"lowerbase driver: waiting for {tty} to appear (looking every 1 s)"]
    finally:
        link.close()
