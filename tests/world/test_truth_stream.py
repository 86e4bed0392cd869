"""The ground truth across processes (lowerbase.world.truth_stream, lowerbase emulate
--truth-udp): datagrams checked against the MCU's own truth, the CSV log of the same run, and
malformed datagrams dropped and counted. ROS-free."""

from __future__ import annotations

import csv
import itertools
import math
import socket
import struct
import time
from pathlib import Path
from typing import Any

import pytest

from lowerbase.cli import main
from lowerbase.errors import ConfigError
from lowerbase.firmware_model.sim import SimRig
from lowerbase.world import truth_stream as ts
from lowerbase.world.truth_stream import TruthReceiver, TruthSample, TruthSender
from tests.conftest import Proc, bus_cli_args


def test_datagram_round_trip_and_layout() -> None:
    sample = TruthSample(12.5, 1.25, -3.5, 7.0, 0.4, -0.3, True, 41, 3)
    data = ts.encode(sample)
    assert len(data) == 62 == ts.FORMAT.size
    assert data[:4] == b"LBTR" and data[4] == 1 and data[5] == 1  # magic, version, contact
    assert struct.unpack_from("<I", data, 6)[0] == 41
    assert struct.unpack_from("<6d", data, 10) == (12.5, 1.25, -3.5, 7.0, 0.4, -0.3)
    assert ts.decode(data) == sample
    assert ts.decode(ts.encode(TruthSample(0, 0, 0, 0, 0, 0))).contact is False


@pytest.mark.parametrize(("text", "expected"), [
    (None, ("127.0.0.1", 43213)), ("", ("127.0.0.1", 43213)), ("5000", ("127.0.0.1", 5000)),
    ("127.0.0.2:6000", ("127.0.0.2", 6000)), ("[::1]:7000", ("::1", 7000)),
])
def test_parse_address(text: str | None, expected: tuple[str, int]) -> None:
    assert ts.parse_address(text) == expected


@pytest.mark.parametrize("text", ["x", "host:", "1:70000", "0", "a:b"])
def test_parse_address_refuses_in_one_line(text: str) -> None:
    with pytest.raises(ConfigError, match=r"expected \[HOST:\]PORT") as info:
        ts.parse_address(text)
    assert "\n" not in str(info.value)


def _send(port: int, *datagrams: bytes) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for d in datagrams:
            s.sendto(d, ("127.0.0.1", port))


def test_malformed_datagrams_are_dropped_and_counted() -> None:
    with TruthReceiver("127.0.0.1", 0) as rx:
        port = rx.address[1]
        good = ts.encode(TruthSample(1.0, 2.0, 3.0, 0.5, 0.1, 0.2, False, seq=5, boot=1))
        nan = bytearray(good)
        struct.pack_into("<d", nan, 18, math.nan)  # x
        version = bytearray(good)
        version[4] = 2
        magic = b"XXXX" + good[4:]
        older = ts.encode(TruthSample(0.9, 9.0, 9.0, 0.0, 0.0, 0.0, False, seq=4, boot=1))
        _send(port, good[:-1], good + b"\0", magic, bytes(version), bytes(nan), good, older,
              good)
        deadline = time.monotonic() + 5.0
        while rx.stats.total() < 8 and time.monotonic() < deadline:
            rx.wait(0.1)
        assert rx.stats == {"bad_size": 2, "bad_magic": 1, "bad_version": 1, "not_finite": 1,
                            "received": 1, "stale": 2}
        assert rx.latest is not None and rx.pose() == (2.0, 3.0, 0.5)
        # a restarted emulator (new boot) starts its sequence again: accepted
        _send(port, ts.encode(TruthSample(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, seq=0, boot=2)))
        assert rx.wait(5.0) and rx.pose() == (0.0, 0.0, 0.0)


def test_receiver_listens_on_loopback_by_default_and_refuses_a_taken_port() -> None:
    with TruthReceiver(port=0) as rx:
        assert rx.address[0] == "127.0.0.1"
        with pytest.raises(ConfigError, match="cannot listen for the ground truth") as info:
            TruthReceiver(port=rx.address[1])
        assert "\n" not in str(info.value)


def test_sender_streams_the_mcus_truth_at_50_hz_on_the_simulated_clock() -> None:
    rig = SimRig(keep=False)
    got: list[TruthSample] = []
    with TruthReceiver("127.0.0.1", 0, on_sample=got.append) as rx:
        sender = TruthSender("127.0.0.1", rx.address[1])
        rig.enable()
        truths: list[tuple[float, ...]] = []
        every = round(0.02 / rig.mcu.dt)
        for k in range(round(4.0 / rig.mcu.dt)):
            if k % every == 0:
                rig.send("MotionCommand", Linear=0.5, Angular=0.4, Mode="Raw")
            rig.step()
            before = sender.sent
            sender(rig.mcu)
            if sender.sent > before:
                tr = rig.mcu.truth
                truths.append((tr.x, tr.y, tr.yaw, tr.v, tr.w))
            rx.drain()
        while rx.wait(0.2):
            pass
        sender.close()
    assert sender.errors == 0 and len(got) == len(truths) == sender.sent
    assert abs(len(got) - 4.0 * 50) <= 1
    assert [s.seq for s in got] == list(range(len(got)))
    dts = [b.t - a.t for a, b in itertools.pairwise(got)]
    assert min(dts) == pytest.approx(0.02, abs=rig.mcu.dt) and max(dts) <= 0.02 + rig.mcu.dt
    # bit-exact: the datagrams carry the MCU's float64 truth, not a rounding of it
    assert [(s.x, s.y, s.yaw, s.v, s.w) for s in got] == truths
    last = got[-1]
    assert math.hypot(last.x, last.y) > 0.5 and last.v == pytest.approx(0.5, rel=0.05)
    assert rig.mcu.boot_counter == last.boot


def test_emulate_streams_the_same_truth_as_its_csv_log(tmp_path: Path,
                                                       udp_bus_config: dict[str, Any]) -> None:
    got: list[TruthSample] = []
    with TruthReceiver("127.0.0.1", 0, on_sample=got.append) as rx:
        log = tmp_path / "truth.csv"
        proc = Proc(["emulate", *bus_cli_args(udp_bus_config), "--simulated", "--duration",
                     "3", "--truth", str(log), "--truth-udp", f"127.0.0.1:{rx.address[1]}"])
        proc.wait_for(f"ground truth to udp 127.0.0.1:{rx.address[1]} at 50 Hz")
        code, err = proc.wait(60.0)
        assert code == 0, err
        while rx.wait(0.5):
            pass
    with log.open() as f:
        rows = list(csv.DictReader(f))
    assert abs(len(rows) - 150) <= 1 and len(got) == len(rows)
    assert rx.stats["received"] == len(rows) and rx.stats.total() == len(rows)
    for row, sample in zip(rows, got, strict=True):
        assert float(row["t"]) == pytest.approx(sample.t, abs=1e-4)
        assert float(row["x"]) == pytest.approx(sample.x, abs=1e-6)
        assert float(row["yaw"]) == pytest.approx(sample.yaw, abs=1e-6)
        assert sample.contact is False


def test_emulate_refuses_a_bad_truth_address(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "--truth-udp", "nowhere:port"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("lowerbase emulate: error: --truth-udp 'nowhere:port'")
    assert err.count("\n") == 1
    assert main(["emulate", "--fleet", "2", "--truth-udp"]) == 1
    assert "drop --truth-udp" in capsys.readouterr().err


def test_emulate_map_installs_the_worlds_contact_and_the_stream_reports_it() -> None:
    """`lowerbase emulate --map empty_room --initial-pose 8,4,0`: driving east, the footprint's
    front (x + 0.4 m) stops at the east wall's inner face, x = 9.8 m on the map."""
    from lowerbase.cli import build_parser
    from lowerbase.cli.emulate import _install_world

    args = build_parser().parse_args(["emulate", "--map", "empty_room", "--initial-pose",
                                      "8,4,0"])
    rig = SimRig(keep=False)
    _install_world(rig.mcu, args)
    got: list[TruthSample] = []
    with TruthReceiver("127.0.0.1", 0, on_sample=got.append) as rx:
        sender = TruthSender("127.0.0.1", rx.address[1])
        rig.enable()
        every = round(0.02 / rig.mcu.dt)
        for k in range(round(8.0 / rig.mcu.dt)):
            if k % every == 0:
                rig.send("MotionCommand", Linear=0.5, Angular=0.0, Mode="Raw")
            rig.step()
            sender(rig.mcu)
            rx.drain()
        while rx.wait(0.2):
            pass
        sender.close()
    front = 8.0 + rig.mcu.truth.x + 0.4
    assert 9.8 - 0.5 * 0.02 <= front <= 9.8 + 1e-9  # within one 20 ms step at 0.5 m/s
    assert rig.mcu.truth.blocked and got[-1].contact and got[-1].v == 0.0
    assert not got[0].contact


def test_emulate_world_options_need_a_map(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "--place", "charger"]) == 1
    assert "go with --map" in capsys.readouterr().err
    assert main(["emulate", "--map", "empty_room", "--initial-pose", "0.1,0.1,0"]) == 1
    err = capsys.readouterr().err
    assert "the robot's start pose" in err and "would touch" in err and err.count("\n") == 1
