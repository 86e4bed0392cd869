"""The emulator warns once when a second lower computer shares its bus (issue 9 item 4)."""

from __future__ import annotations

import itertools
import logging

import can
import pytest

from lowerbase.clock import SimClock
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import bus_sender, run
from lowerbase.protocol.codec import default_codec
from lowerbase.transport.peers import PeerMonitor

_channels = itertools.count()
WARNING = "two lower computers on one bus"


class Rig:
    """Emulator A run by the runner on a virtual bus that echoes its own frames (as
    udp_multicast does); optionally a second emulator B, stepped on the same simulated clock,
    joining the bus at ``second_at`` [s]."""

    def __init__(self, second_at: float | None) -> None:
        channel = f"two-lower-{next(_channels)}"
        self.clock = SimClock(50.0)
        self.start = self.clock.now()
        self.bus_a = can.Bus(interface="virtual", channel=channel, receive_own_messages=True)
        self.bus_b = can.Bus(interface="virtual", channel=channel)
        self.peers = PeerMonitor(default_codec())
        send = bus_sender(self.bus_a, on_sent=lambda fid, data: self.peers.on_sent(
            fid, data, self.clock.now()))
        self.a = Mcu(load_profile(), self.clock, send)
        self.b: Mcu | None = None
        self.second_at = second_at
        self.warned_at: float | None = None

    def step(self, mcu: Mcu) -> None:
        now = self.clock.now() - self.start
        if self.second_at is not None and self.b is None and now >= self.second_at:
            self.b = Mcu(load_profile(), self.clock, bus_sender(self.bus_b))
        if self.b is not None:
            self.b.step()
        if self.warned_at is None and mcu.stats["two_lower_computers"]:
            self.warned_at = now

    def run(self, seconds: float) -> None:
        try:
            run(self.a, self.bus_a, self.clock, duration=seconds, on_step=self.step,
                peers=self.peers)
        finally:
            self.bus_a.shutdown()
            self.bus_b.shutdown()


def _warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.levelno == logging.WARNING and WARNING in r.getMessage()]


def test_one_emulator_hearing_its_own_frames_does_not_warn(
        caplog: pytest.LogCaptureFixture) -> None:
    rig = Rig(second_at=None)
    with caplog.at_level(logging.WARNING):
        rig.run(30.0)
    assert rig.a.stats["rx_frames"] > 1000  # it did hear itself (looped back)
    assert rig.a.stats["two_lower_computers"] == 0
    assert _warnings(caplog) == []


def test_a_second_emulator_on_the_bus_is_warned_about_once(
        caplog: pytest.LogCaptureFixture) -> None:
    rig = Rig(second_at=7.0)
    with caplog.at_level(logging.WARNING):
        rig.run(30.0)
    assert rig.warned_at is not None and 7.0 < rig.warned_at <= 9.0
    assert rig.a.stats["two_lower_computers"] == 1
    warnings = _warnings(caplog)
    assert len(warnings) == 1  # once, not every Heartbeat for the next 21 s
    assert "stop one" in warnings[0] and "BootCounter 1" in warnings[0]
