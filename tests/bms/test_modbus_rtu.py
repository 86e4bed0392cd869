"""The BMS's Modbus RTU side: frames cut out by length, CRC and silence; the same answers as TCP.

The CRCs are computed with pymodbus' own RTU framer, an implementation independent of ours.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import serial
from pymodbus.framer import FramerRTU

from lowerbase.bms.device import BmsDevice, BmsServer
from lowerbase.bms.modbus import RtuFramer, SlaveCore, crc16
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.ptybridge import PtyBridge


def frame(text: str) -> bytes:
    body = bytes.fromhex(text)
    return body + FramerRTU.compute_CRC(body).to_bytes(2, "big")


def test_crc_matches_the_standard_example() -> None:
    # "01 03 00 00 00 0a" -> CRC c5 cd on the wire, the classic example
    assert crc16(bytes.fromhex("01 03 00 00 00 0a")).to_bytes(2, "little") == b"\xc5\xcd"


@pytest.fixture
def framer() -> tuple[RtuFramer, list[bytes]]:
    sent: list[bytes] = []
    return RtuFramer(SlaveCore(BmsDevice(BatteryPack(soc=50.0))), sent.append), sent


def test_framer_cuts_by_length_and_waits_for_silence(
    framer: tuple[RtuFramer, list[bytes]],
) -> None:
    rtu, sent = framer
    read = frame("01 03 01 00 00 02")
    rtu.feed(read[:3])
    rtu.feed(read[3:] + read)  # a split frame, then a whole one: both answered at once
    assert sent == [frame("01 03 04 0e 42 0d ac")] * 2
    sent.clear()
    rtu.feed(frame("01 07"))  # length unknown: answered after the silence
    assert sent == []
    rtu.silence()
    assert sent == [frame("01 87 01")]


def test_framer_drops_noise_and_resynchronises(framer: tuple[RtuFramer, list[bytes]]) -> None:
    rtu, sent = framer
    rtu.feed(b"\x01\x03\xff\x00\x00\x02\x00\x00" + frame("01 03 01 00 00 02"))  # bad CRC first
    assert sent == []
    rtu.silence()
    assert sent == [] and rtu.core.dropped["RTU noise or bad CRC"] == 1
    rtu.feed(frame("01 03 01 00 00 02"))
    assert sent == [frame("01 03 04 0e 42 0d ac")]


@pytest.fixture
def port() -> Iterator[tuple[serial.Serial, BmsServer]]:
    device = BmsDevice(BatteryPack(soc=72.0), unit=1)
    with PtyBridge() as bridge:
        server = BmsServer(device, tcp=None, rtu=bridge.a_path)
        server.start()
        ser = serial.Serial(bridge.b_path, 19200, timeout=5.0)
        try:
            yield ser, server
        finally:
            ser.close()
            server.stop()


@pytest.mark.parametrize(
    ("request_frame", "answer"),
    [
        ("01 03 01 00 00 02", "01 03 04 0e 42 0d ac"),
        ("01 03 01 00 00 00", "01 83 03"),  # quantity 0
        ("01 04 00 00 00 7e", "01 84 03"),  # quantity 126
        ("01 03 01 00 00", "01 83 03"),  # short PDU (answered after the silence)
        ("01 10 01 00 00 01 04 0e 42", "01 90 03"),  # byte count mismatch
        ("01 03 00 00 00 01", "01 83 02"),
        ("01 06 01 00 0e 10", "01 86 03"),
        ("01 07", "01 87 01"),
        ("01 08 00 00 12 34", "01 88 01"),
        ("01 11", "01 91 01"),
        ("01 2b 0e 01 00", "01 ab 01"),
    ],
)
def test_rtu_answers_like_tcp(
    port: tuple[serial.Serial, BmsServer], request_frame: str, answer: str
) -> None:
    ser, _ = port
    ser.write(frame(request_frame))
    expected = frame(answer)
    assert ser.read(len(expected)).hex(" ") == expected.hex(" ")


def test_rtu_other_units_and_broadcasts(port: tuple[serial.Serial, BmsServer]) -> None:
    ser, server = port
    ser.write(frame("02 03 01 00 00 02"))  # another slave's request: silence
    ser.write(frame("00 06 01 00 0e 74"))  # broadcast write: executed, not answered
    ser.write(frame("01 03 01 00 00 02"))
    expected = frame("01 03 04 0e 74 0d ac")
    assert ser.read(len(expected)).hex(" ") == expected.hex(" ")
    assert server.dropped["other unit id"] == 1
