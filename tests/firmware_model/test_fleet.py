"""The fleet runner: N chassis on one simulated clock, each on its own bus with its own state."""

from __future__ import annotations

import select
import socket
import subprocess
import sys
from typing import Any

import can
import pytest

from lowerbase.clock import SimClock
from lowerbase.errors import ConfigError
from lowerbase.firmware_model.mcu import Command, Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import (
    SIM_BLOCK,
    Chassis,
    bus_sender,
    close_fleet,
    fleet_bus_configs,
    fleet_profile,
    open_fleet,
    run,
    run_fleet,
)
from lowerbase.protocol.codec import default_codec
from lowerbase.transport import free_loopback_port, open_bus
from lowerbase.transport.udp_wire import pack_classic

CODEC = default_codec()


class Upper:
    """Plays the upper computer of one chassis: enable after boot, then drive."""

    def __init__(self, bus: can.BusABC, linear: float, angular: float) -> None:
        self.bus, self.linear, self.angular = bus, linear, angular
        self.steps = self.counter = self.sent = 0

    def send(self, name: str, **values: Any) -> None:
        msg = CODEC.message(name)
        if msg.has_counter:
            values["Counter"] = self.counter
            self.counter = (self.counter + 1) & 0xF
        self.bus.send(can.Message(arbitration_id=msg.frame_id, data=msg.encode(values),
                                  is_extended_id=False))
        self.sent += 1

    def __call__(self, *_: Any) -> None:
        self.steps += 1
        if self.steps == 80:
            self.send("ControlCommand", Command="EnableCanControl")
        elif self.steps > 80 and self.steps % 4 == 0:
            self.send("MotionCommand", Linear=self.linear, Angular=self.angular, Mode="Raw")


def test_bus_of_each_chassis() -> None:
    udp = {"interface": "udp_multicast", "channel": "239.74.163.2", "port": 43113,
           "hop_limit": 0}
    assert [c["port"] for c in fleet_bus_configs(udp, 3)] == [43113, 43114, 43115]
    assert all(c["channel"] == "239.74.163.2" for c in fleet_bus_configs(udp, 3))
    virtual = fleet_bus_configs({"interface": "virtual", "channel": "f"}, 2)
    assert [c["channel"] for c in virtual] == ["f/0", "f/1"]
    with pytest.raises(ConfigError, match="udp_multicast"):
        fleet_bus_configs({"interface": "socketcan", "channel": "vcan0"}, 2)
    with pytest.raises(ConfigError, match="lower port"):
        fleet_bus_configs({**udp, "port": 65000}, 600)
    with pytest.raises(ConfigError, match="at least one"):
        fleet_bus_configs(udp, 0)


def test_each_chassis_has_its_own_seeds() -> None:
    p = load_profile()
    seeds = {(fleet_profile(p, k).imu.seed, fleet_profile(p, k).truth.seed) for k in range(5)}
    assert len(seeds) == 5 and fleet_profile(p, 0) == p
    assert fleet_profile(p, 3).chassis == p.chassis  # the same robot otherwise


def test_a_fleet_chassis_runs_exactly_as_one_chassis_alone() -> None:
    """Chassis 0 of a fleet of 3 (virtual buses, one driven) ends bit for bit where the same
    chassis run alone by ``run`` ends; the others, not driven, stay where they started."""
    p = load_profile()
    clock = SimClock()
    fleet = open_fleet(p, clock, {"interface": "virtual", "channel": "test_fleet_a"}, 3,
                       bms=False)
    uppers = [can.Bus(interface="virtual", channel=f"test_fleet_a/{k}") for k in range(3)]
    drive = Upper(uppers[0], 0.5, 0.3)
    try:
        run_fleet(fleet, clock, duration=3.0, on_step=drive)
        truths = [c.mcu.truth for c in fleet]
        heard = [c.mcu.stats["rx_frames"] for c in fleet]
    finally:
        close_fleet(fleet)
        for bus in uppers:
            bus.shutdown()
    assert clock.now() == pytest.approx(3.0)

    alone_clock = SimClock()
    bus = open_bus(interface="virtual", channel="test_fleet_alone")
    upper = can.Bus(interface="virtual", channel="test_fleet_alone")
    try:
        mcu = Mcu(p, alone_clock, bus_sender(bus))
        run(mcu, bus, alone_clock, duration=3.0, on_step=Upper(upper, 0.5, 0.3))
    finally:
        bus.shutdown()
        upper.shutdown()
    assert (truths[0].x, truths[0].y, truths[0].yaw) == (mcu.truth.x, mcu.truth.y, mcu.truth.yaw)
    assert truths[0].x > 0.5
    # all it was sent but the command sent after the last step
    assert heard[0] == drive.sent - 1 == 130 and heard[1] == heard[2] == 0
    for other in truths[1:]:
        assert (other.x, other.y, other.yaw) == (0.0, 0.0, 0.0)


def _wait_readable(bus: can.BusABC) -> None:
    """Until a frame sent to ``bus`` has arrived (bounded: the kernel delivers it at once)."""
    ready, _, _ = select.select([bus.fileno()], [], [], 5.0)
    assert ready, "a frame sent on loopback did not arrive"


def test_each_chassis_is_on_its_own_udp_multicast_bus(udp_bus_config: dict[str, Any]) -> None:
    clock = SimClock()
    fleet = open_fleet(load_profile(), clock, udp_bus_config, 3)
    uppers = [open_bus(cfg) for cfg in fleet_bus_configs(udp_bus_config, 3)]
    drive = Upper(uppers[1], 0.4, 0.0)

    def on_step() -> None:
        before = drive.counter
        drive()
        if drive.counter != before or drive.steps == 80:  # sent something: let it arrive
            _wait_readable(fleet[1].bus)

    try:
        run_fleet(fleet, clock, duration=2.0, on_step=on_step)
        got: list[list[can.Message]] = []
        for bus in uppers:
            frames = []
            while (msg := bus.recv(0.2)) is not None:
                frames.append(msg)
            got.append(frames)
        sent = [c.mcu.stats["tx_frames"] for c in fleet]
        moved = [c.mcu.truth.x for c in fleet]
    finally:
        close_fleet(fleet)
        for bus in uppers:
            bus.shutdown()
    # every upper side heard exactly its own chassis' frames, all of them
    assert [len(frames) for frames in got] == sent
    assert moved[1] > 0.3 and moved[0] == moved[2] == 0.0
    motion = CODEC.message("MotionState")

    def linear(frames: list[can.Message]) -> float:
        last = [m for m in frames if m.arbitration_id == motion.frame_id][-1]
        return float(motion.decode(bytes(last.data))["Linear"])

    assert linear(got[1]) == pytest.approx(0.4, abs=0.02)
    assert linear(got[0]) == linear(got[2]) == 0.0
    gyro = CODEC.message("ImuGyro").frame_id
    imu = [[bytes(m.data) for m in frames if m.arbitration_id == gyro] for frames in got]
    assert imu[0] != imu[2]  # their own IMU noise (seed + k)


def test_emulate_fleet_command(udp_bus_config: dict[str, Any]) -> None:
    from tests.conftest import bus_cli_args

    port = udp_bus_config["port"]
    done = subprocess.run(
        [sys.executable, "-m", "lowerbase", "emulate", "--fleet", "3", "--simulated",
         "--duration", "1", *bus_cli_args(udp_bus_config)],
        capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "fleet of 3 lower computers" in done.stdout
    assert f"ports {port}..{port + 2} (chassis k on port {port}+k)" in done.stdout
    assert "all 3 together: tx_frames" in done.stderr and "Traceback" not in done.stderr
    refused = subprocess.run(
        [sys.executable, "-m", "lowerbase", "emulate", "--fleet", "2", "--truth", "t.csv",
         "--duration", "1", *bus_cli_args(udp_bus_config)],
        capture_output=True, text=True, timeout=60)
    assert refused.returncode != 0
    assert refused.stderr.strip().splitlines() == [
        "lowerbase emulate: error: --fleet runs each chassis with its own pack on its own bus; "
        "drop --truth"]


def _drained(bus: can.BusABC, timeout: float) -> list[tuple[int, bytes]]:
    """(id, data) of every frame ``bus`` has, until none arrives within ``timeout`` [s]."""
    frames = []
    while (msg := bus.recv(timeout)) is not None:
        frames.append((msg.arbitration_id, bytes(msg.data)))
    return frames


def _blocked_run(block: int, duration: float, channel: str
                 ) -> tuple[list[list[tuple[int, bytes]]], list[tuple[float, float, float]],
                            list[int], float]:
    """A fleet of 3 on virtual buses, each chassis driven by its own upper side (sent after
    each of its steps), run with ``block`` periods per chassis at a time: (each upper side's
    frames heard, each chassis' true pose, each chassis' rx count, the clock at the end)."""
    clock = SimClock()
    fleet = open_fleet(load_profile(), clock, {"interface": "virtual", "channel": channel}, 3)
    uppers = [can.Bus(interface="virtual", channel=f"{channel}/{k}") for k in range(3)]
    drives = [Upper(uppers[k], 0.3 + 0.1 * k, 0.2 * k) for k in range(3)]
    try:
        run_fleet(fleet, clock, duration=duration, block=block,
                  on_chassis_step=lambda k, _: drives[k]())
        heard = [_drained(bus, 0.0) for bus in uppers]
        poses = [(c.mcu.truth.x, c.mcu.truth.y, c.mcu.truth.yaw) for c in fleet]
        rx = [c.mcu.stats["rx_frames"] for c in fleet]
    finally:
        close_fleet(fleet)
        for bus in uppers:
            bus.shutdown()
    return heard, poses, rx, clock.now()


def test_a_fleet_stepped_in_blocks_is_bit_identical_to_period_by_period() -> None:
    """run_fleet's simulated-clock blocks (each chassis several periods at a time, for the
    CPU caches) send the same frames, end at the same true poses and the same time, and hand
    each chassis the same frames at the same step as the period-by-period loop; also when the
    duration is not a whole number of blocks."""
    by_period = _blocked_run(1, 2.03, "test_fleet_blk1")
    in_blocks = _blocked_run(SIM_BLOCK, 2.03, "test_fleet_blk")  # the default block
    assert round(2.03 / 0.005) % SIM_BLOCK != 0  # 2.03 s is not a whole number of blocks
    heard, poses, rx, end = by_period
    assert in_blocks == by_period
    assert end == pytest.approx(2.03) and all(len(frames) > 700 for frames in heard)
    assert rx == [82, 82, 82] and poses[2][2] > 0.2  # driven: enabled, commands, turning


def test_bus_sender_reports_the_watched_ids_and_counts_refusals(
        udp_bus_config: dict[str, Any]) -> None:
    """``sent_ids``: on_sent sees only those frames (a PeerMonitor reads Heartbeats); every
    frame still reaches the bus; a refused frame is counted and not reported as sent."""
    bus, upper = open_bus(udp_bus_config), open_bus(udp_bus_config)
    seen: list[int] = []
    errors: list[str] = []
    send = bus_sender(bus, errors.append, on_sent=lambda fid, _: seen.append(fid),
                      sent_ids=(0x700,))
    try:
        send(0x700, b"\x01")
        send(0x123, b"\x02")
        heard = [upper.recv(2.0) for _ in range(2)]
        assert [(m.arbitration_id, bytes(m.data)) for m in heard if m is not None] == [
            (0x700, b"\x01"), (0x123, b"\x02")]
        assert seen == [0x700] and errors == []
    finally:
        bus.shutdown()
        upper.shutdown()
    send(0x700, b"\x03")  # the bus is closed: refused
    assert errors == ["tx_errors"] and seen == [0x700]


def test_a_second_lower_computer_on_one_chassis_bus_is_noticed(
        udp_bus_config: dict[str, Any]) -> None:
    """The fleet's PeerMonitors learn their own Heartbeats from what is sent (only Heartbeats
    are handed to them): a lower computer joining chassis 1's bus, and only it, is a second
    lower computer there (it is the only stream that bus hears: without the chassis' own
    Heartbeats it would look like the one lower computer on the bus)."""
    clock = SimClock()
    fleet = open_fleet(load_profile(), clock, udp_bus_config, 3, bms=False)
    intruder_bus = open_bus(fleet_bus_configs(udp_bus_config, 3)[1])
    beats: list[int] = []
    intruder = Mcu(fleet_profile(load_profile(), 7), clock, bus_sender(
        intruder_bus, on_sent=lambda fid, _: beats.append(fid),
        sent_ids=(CODEC.message("Heartbeat").frame_id,)))

    def on_step() -> None:
        intruder.step()
        if beats:  # a Heartbeat went out: let it arrive
            _wait_readable(fleet[1].bus)
            beats.clear()

    try:
        run_fleet(fleet, clock, duration=4.0, on_step=on_step)
        flagged = [c.mcu.stats["two_lower_computers"] for c in fleet]
        peers = [c.peers for c in fleet]
    finally:
        close_fleet(fleet)
        intruder_bus.shutdown()
    assert flagged == [0, 1, 0]
    assert peers[1] is not None and "this one and one with" in peers[1].warning


def _udp_fleet_frames(config: dict[str, Any], block: int) -> tuple[list[list[tuple[int, bytes]]],
                                                                   list[int]]:
    """A fleet of 2 on udp_multicast driven by direct commands, 1.03 s in ``block``-period
    blocks: (what each chassis' upper side heard, each chassis' tx_frames)."""
    clock = SimClock()
    fleet = open_fleet(load_profile(), clock, config, 2, bms=False)
    uppers = [open_bus(cfg) for cfg in fleet_bus_configs(config, 2)]

    steps = [0, 0]

    def drive(k: int, chassis: Chassis) -> None:  # after each step of chassis k
        steps[k] += 1
        if steps[k] == 70:
            chassis.mcu.control(Command.ENABLE_CAN_CONTROL)
        elif steps[k] % 4 == 0:
            chassis.mcu.command(0.3 + 0.2 * k, 0.1)

    try:
        run_fleet(fleet, clock, duration=1.03, block=block, on_chassis_step=drive)
        heard = [_drained(bus, 0.2) for bus in uppers]
        return heard, [c.mcu.stats["tx_frames"] - c.mcu.stats["tx_errors"] for c in fleet]
    finally:
        close_fleet(fleet)
        for bus in uppers:
            bus.shutdown()


def test_a_udp_fleet_sends_a_blocks_frames_in_one_go_all_in_order(
        udp_bus_config: dict[str, Any]) -> None:
    """On udp_multicast a chassis' frames are held while it runs a block and sent after it:
    each upper side hears every frame of its chassis, the same ones in the same order as
    when the fleet steps period by period."""
    by_period, sent = _udp_fleet_frames(udp_bus_config, 1)
    in_blocks, sent_blocks = _udp_fleet_frames(
        {**udp_bus_config, "port": free_loopback_port()}, SIM_BLOCK)
    assert in_blocks == by_period and sent == sent_blocks
    assert [len(frames) for frames in by_period] == sent and min(sent) > 300


@pytest.mark.parametrize("block", [1, SIM_BLOCK])
def test_on_chassis_step_sees_the_clock_of_the_period_it_ran(block: int) -> None:
    """Period by period or in blocks, ``on_chassis_step`` runs after the chassis' step and
    before the clock moves on: it reads the time of the period just stepped."""
    clock = SimClock()
    config = {"interface": "virtual", "channel": f"c2-clock-{block}"}
    fleet = open_fleet(load_profile(), clock, config, 2, bms=False)
    seen: list[tuple[int, float]] = []
    try:
        run_fleet(fleet, clock, duration=0.5, block=block,
                  on_chassis_step=lambda k, c: seen.append((k, c.mcu.clock.now())))
    finally:
        close_fleet(fleet)
    expected, t = [], 0.0
    for _ in range(100):
        expected += [(0, t), (1, t)]
        t += fleet[0].mcu.dt
    assert sorted(seen) == sorted(expected)


def _send_garbage_then_enable(config: dict[str, Any]) -> None:
    """An upper computer on the group: a datagram that is no frame, then EnableCanControl."""
    control = CODEC.message("ControlCommand")
    enable = pack_classic(control.frame_id, control.encode({"Command": "EnableCanControl"}))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as upper:
        upper.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        upper.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
        for datagram in (b"not msgpack \xc1", enable):
            upper.sendto(datagram, (config["channel"], config["port"]))


def test_a_fleet_reads_the_frames_behind_a_datagram_that_is_no_frame(
        udp_bus_config: dict[str, Any]) -> None:
    """A datagram on the group that is not a frame is dropped and counted; the command right
    behind it reaches the chassis in the same period (the drain reads past it)."""
    clock = SimClock()
    fleet = open_fleet(load_profile(), clock, udp_bus_config, 1, bms=False)
    chassis = fleet[0]
    try:
        run_fleet(fleet, clock, duration=0.4)  # boot
        _send_garbage_then_enable(udp_bus_config)
        assert select.select([chassis.bus], [], [], 2.0)[0]
        run_fleet(fleet, clock, duration=chassis.mcu.dt)  # one period
        assert chassis.mcu.stats["control_enable_can_control"] == 1
        assert chassis.bus.rx_malformed == 1  # type: ignore[attr-defined]
    finally:
        close_fleet(fleet)


def test_one_chassis_on_the_simulated_clock_reads_past_a_datagram_that_is_no_frame(
        udp_bus_config: dict[str, Any]) -> None:
    """runner.run (``lowerbase emulate --simulated``): as the fleet, the command behind a
    datagram that is not a frame is read in the same period."""
    clock = SimClock()
    bus = open_bus(udp_bus_config)
    mcu = Mcu(load_profile(), clock, bus_sender(bus))
    try:
        run(mcu, bus, clock, duration=0.4)  # boot
        _send_garbage_then_enable(udp_bus_config)
        assert select.select([bus], [], [], 2.0)[0]
        run(mcu, bus, clock, duration=mcu.dt)  # one period
        assert mcu.stats["control_enable_can_control"] == 1
        assert bus.rx_malformed == 1  # type: ignore[attr-defined]
    finally:
        mcu.shutdown()
        bus.shutdown()
