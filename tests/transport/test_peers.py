"""PeerMonitor: two lower computers on one bus, told apart from a reboot or a forged frame."""

from __future__ import annotations

from collections.abc import Callable

from lowerbase.clock import SimClock
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.protocol.codec import default_codec
from lowerbase.transport.peers import PeerMonitor

CODEC = default_codec()
HEARTBEAT = CODEC.message("Heartbeat")
Frames = list[tuple[float, int, bytes, int]]  # (stamp, frame id, data, which MCU)


class Bus:
    """Emulated MCUs on one simulated clock; every frame they send is kept with its time."""

    def __init__(self) -> None:
        self.clock = SimClock(100.0)
        self.frames: Frames = []
        self.mcus: list[Mcu] = []

    def add(self) -> Mcu:
        which = len(self.mcus)
        mcu = Mcu(load_profile(), self.clock, self._sender(which))
        self.mcus.append(mcu)
        return mcu

    def _sender(self, which: int) -> Callable[[int, bytes], None]:
        return lambda frame_id, data: self.frames.append(
            (self.clock.now(), frame_id, data, which))

    def run(self, seconds: float, mcus: list[Mcu] | None = None) -> None:
        for _ in range(round(seconds / 0.01)):
            for mcu in self.mcus if mcus is None else mcus:
                mcu.step()
            self.clock.advance(0.01)


def first_conflict(frames: Frames, monitor: PeerMonitor | None = None) -> float | None:
    monitor = monitor or PeerMonitor()
    hits = [stamp for stamp, fid, data, _ in frames if monitor.on_frame(fid, data, stamp)]
    assert len(hits) <= 1  # True once only
    return hits[0] if hits else None


def test_one_lower_computer_is_one() -> None:
    bus = Bus()
    bus.add()
    bus.run(30.0)
    monitor = PeerMonitor()
    assert first_conflict(bus.frames, monitor) is None
    assert monitor.lower_computers == 1
    assert not monitor.conflict and monitor.warning == ""


def test_a_second_lower_computer_is_noticed_within_two_seconds() -> None:
    bus = Bus()
    bus.add()
    bus.run(7.3)
    second_boot = bus.clock.now()
    bus.add()
    bus.run(10.0)
    monitor = PeerMonitor()
    seen = first_conflict(bus.frames, monitor)
    assert seen is not None and second_boot < seen <= second_boot + 2.0
    assert monitor.conflict and monitor.lower_computers == 2
    assert "two lower computers on one bus" in monitor.warning
    assert monitor.warning.count("BootCounter 1, uptime") == 2  # names what it saw


def test_two_started_at_almost_the_same_time_are_told_apart_by_their_counters() -> None:
    bus = Bus()
    bus.add()
    bus.run(0.02)
    bus.add()  # uptimes differ by 20 ms only, the same BootCounter
    bus.run(5.0)
    assert first_conflict(bus.frames) is not None


def test_a_reboot_is_not_a_second_lower_computer() -> None:
    bus = Bus()
    mcu = bus.add()
    bus.run(10.0)
    mcu.power_on()  # reboots in place: the old Heartbeats stop, new ones start at uptime 0
    bus.run(10.0)
    bus.run(3.0, mcus=[])  # killed, silent...
    bus.mcus.clear()
    bus.add()  # ...and started again: BootCounter 1 again, as without a parameter file
    bus.run(10.0)
    assert first_conflict(bus.frames) is None


def test_forged_heartbeats_are_not_a_second_lower_computer() -> None:
    bus = Bus()
    bus.add()
    bus.run(10.0)
    forged = HEARTBEAT.encode({"Uptime": 10.2, "BootCounter": 7, "Counter": 3,
                               "ProtocolVersion": 1, "Overruns": 0})
    bus.frames.append((bus.clock.now(), HEARTBEAT.frame_id, forged, 9))
    bus.frames.append((bus.clock.now(), HEARTBEAT.frame_id, b"\x01\x02", 9))  # garbled
    bus.run(10.0)
    assert first_conflict(bus.frames) is None


def test_a_lower_computer_hears_itself_back_without_alarm_and_notices_another() -> None:
    bus = Bus()
    bus.add()
    bus.run(10.0)
    monitor = PeerMonitor()
    for stamp, fid, data, _ in bus.frames:  # on udp_multicast its own frames loop back
        monitor.on_sent(fid, data, stamp)
        assert not monitor.on_frame(fid, data, stamp)
    assert monitor.lower_computers == 0  # only itself
    other = Bus()
    other.clock = bus.clock
    other.add()
    start = len(bus.frames)
    other.run(3.0)
    own = [(bus.clock.now() - 3.0 + i * 0.5) for i in range(6)]
    for stamp in own:  # it keeps sending its own Heartbeats meanwhile
        monitor.on_sent(HEARTBEAT.frame_id, HEARTBEAT.encode(
            {"Uptime": stamp - 100.0, "BootCounter": 1, "Counter": 0, "ProtocolVersion": 1,
             "Overruns": 0}),
            stamp)
    assert start == len(bus.frames)
    hits = [stamp for stamp, fid, data, _ in other.frames if monitor.on_frame(fid, data, stamp)]
    assert len(hits) == 1
    assert "this one and one with" in monitor.warning


def test_a_lower_computer_whose_time_slipped_stays_one_stream() -> None:
    """Its Uptime fell 1.5 s behind the receiver's clock and its Overruns say so (issue 22
    item 3): the same stream, not a new one that a second lower computer could start."""
    monitor = PeerMonitor()
    for k in range(12):
        uptime = 10.0 + 0.5 * k
        slipped = k >= 6
        data = HEARTBEAT.encode({"Uptime": uptime, "BootCounter": 1, "Counter": k % 16,
                                 "ProtocolVersion": 1, "Overruns": int(slipped)})
        assert not monitor.on_frame(HEARTBEAT.frame_id, data, uptime + 1.5 * slipped)
    assert len(monitor.streams) == 1 and monitor.streams[0].count == 12
