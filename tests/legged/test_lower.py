"""The legged lower computer's frame loop on the simulated clock: every actuator answers every
command, frame rates per bus, body frames at their DBC cycles, requests per the state table,
raw actuator commands only in IN_TEST_MODE, the velocity watchdog, body temperature against
the closed form, the BMS relayed in Bms* frames that the wheeled accumulator decodes, faults."""

from __future__ import annotations

import itertools
import math
from collections import Counter
from dataclasses import replace

import pytest

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.bms.device import BmsDevice
from lowerbase.bms.frames import BmsFrameAccumulator
from lowerbase.bms.pack import BatteryPack
from lowerbase.clock import SimClock
from lowerbase.legged.lower import LeggedLower
from lowerbase.legged.profile import LeggedProfile
from lowerbase.legged.thermal import BodyThermal
from lowerbase.protocol.legged import (
    COMMAND_MESSAGES,
    REPLY_ID,
    REPLY_PREFIX,
    Fault,
    LocomotionState,
    RequestResult,
    Special,
    joint_address,
    legged_codec,
    parse_special,
    special_frame,
)

S = LocomotionState
CODEC = legged_codec()
Frame = tuple[float, int, int, bytes]


class Rig:
    """A lower computer on a simulated clock with every frame it sends recorded."""

    def __init__(self, profile: LeggedProfile | None = None, bms: bool = True,
                 soc: float = 80.0) -> None:
        self.profile = profile or LeggedProfile()
        self.clock = SimClock()
        self.frames: list[Frame] = []
        adapter = McuBmsAdapter(BmsDevice(BatteryPack(self.profile.battery, soc=soc)),
                                critical_soc=self.profile.power.critical_battery_soc) \
            if bms else None
        self.lower = LeggedLower(self.profile, self.clock, self.send, bms=adapter)

    def send(self, bus: int, frame_id: int, data: bytes) -> None:
        self.frames.append((self.clock.now(), bus, frame_id, data))

    def run(self, seconds: float, cmd: tuple[float, float, float] | None = None) -> None:
        for i in range(round(seconds / self.lower.dt)):
            if cmd is not None and i % 20 == 0:  # BodyVelocityCommand's 20 ms cycle
                self.body_frame("BodyVelocityCommand",
                                {"Vx": cmd[0], "Vy": cmd[1], "YawRate": cmd[2], "Counter": 0})
            self.lower.step()
            self.clock.advance(self.lower.dt)

    def body_frame(self, name: str, values: dict[str, float | int]) -> None:
        self.lower.receive(0, CODEC.message(name).frame_id, CODEC.encode(name, values))

    def request(self, state: LocomotionState) -> None:
        self.body_frame("LocomotionRequest", {"Request": int(state), "Counter": 0})

    def stand(self) -> None:
        for state in (S.COMM_ENABLED, S.MOTOR_READY, S.MOTOR_ENABLED):
            self.request(state)
            self.run(0.6)
        self.request(S.STANDING_MODE)
        self.run(1.2)
        assert self.lower.body.state is S.STANDING_MODE

    def last(self, name: str) -> dict[str, float]:
        fid = CODEC.message(name).frame_id
        data = next(d for _, b, i, d in reversed(self.frames) if b == 0 and i == fid)
        return {k: float(v) for k, v in CODEC.decode(fid, data)[1].items()}


def test_each_actuator_answers_each_command_and_rates_per_bus() -> None:
    rig = Rig()
    rig.stand()
    rig.request(S.IN_CONTROL)
    rig.frames.clear()
    t0 = rig.clock.now()
    rig.run(2.0, (0.8, 0.0, 0.3))
    assert rig.lower.body.state is S.IN_CONTROL
    per_bus = Counter((b, i) for _, b, i, _ in rig.frames)
    for bus in range(4):
        assert per_bus[(bus, REPLY_ID)] == 3 * 2000  # 3 actuators x 1 kHz
        for mid in COMMAND_MESSAGES:
            assert per_bus[(bus, mid)] == 2000
        # command then its reply, per actuator, in order
        wire = [(i, d) for _, b, i, d in rig.frames if b == bus and i in (0, 1, 2, 3)]
        for (cmd_id, _), (reply_id, reply) in zip(wire[::2], wire[1::2], strict=True):
            assert reply_id == REPLY_ID and reply[0] == cmd_id
    # body frames only on bus 0, at their DBC cycle times
    for m in CODEC:
        if m.frame_id >= 0x80 and m.cycle_time:
            assert per_bus[(0, m.frame_id)] == round(2.0 / m.cycle_time), m.name
            assert sum(per_bus[(b, m.frame_id)] for b in (1, 2, 3)) == 0
    # rolling counters +1 mod 16 per frame
    counters = [int(CODEC.decode(i, d)[1]["Counter"]) for _, b, i, d in rig.frames
                if b == 0 and i == CODEC.message("LocomotionStatus").frame_id]
    assert all((b - a) % 16 == 1 for a, b in itertools.pairwise(counters))
    assert all(t0 <= t < t0 + 2.0 for t, *_ in rig.frames)


def test_replies_carry_the_actuators_state() -> None:
    rig = Rig()
    rig.stand()
    for index, a in enumerate(rig.lower.body.actuators):
        bus, mid = joint_address(index)
        reply = next(d for _, b, i, d in reversed(rig.frames)
                     if b == bus and i == REPLY_ID and d[0] == mid)
        s = CODEC.decode(REPLY_ID, reply)[1]
        p = REPLY_PREFIX[mid]
        assert s[f"{p}Position"] == pytest.approx(a.reported_position, abs=4e-4)
        assert s[f"{p}Velocity"] == pytest.approx(a.velocity, abs=0.02)
        assert s[f"{p}Torque"] == pytest.approx(a.torque, abs=0.015)
        assert s["Temperature"] == round(a.temperature) and s["Error"] == 0
    # the standing pose: the base height reported equals the profile's
    assert rig.last("BasePosition")["Z"] == pytest.approx(rig.profile.body.stand_height,
                                                          abs=1e-3)


def test_special_frames_on_commutation_and_disable() -> None:
    rig = Rig()
    rig.request(S.COMM_DISABLED)
    rig.run(0.01)
    assert not any(i in COMMAND_MESSAGES for _, _, i, _ in rig.frames)  # silent bus
    rig.request(S.COMM_ENABLED)
    rig.request(S.MOTOR_READY)
    rig.run(0.01)
    rig.frames.clear()
    rig.request(S.MOTOR_ENABLED)
    rig.run(0.002)
    first = [(b, i, parse_special(d)) for _, b, i, d in rig.frames if i in COMMAND_MESSAGES]
    assert first[:12] == [(*joint_address(k), Special.ENTER_MOTOR_MODE) for k in range(12)]
    assert all(s is None for *_, s in first[12:])
    rig.run(0.6)
    assert all(a.motor_mode for a in rig.lower.body.actuators)
    rig.frames.clear()
    rig.request(S.MOTOR_DISABLED)
    rig.run(0.001)
    specials = {parse_special(d) for _, _, i, d in rig.frames if i in COMMAND_MESSAGES}
    assert specials == {Special.EXIT_MOTOR_MODE}


def test_requests_follow_the_state_table() -> None:
    rig = Rig()
    rig.request(S.IN_CONTROL)  # not allowed from COMM_DISABLED
    rig.run(0.02)
    s = rig.last("LocomotionStatus")
    assert (s["State"], s["LastRequest"], s["RequestResult"]) == (
        S.COMM_DISABLED, S.IN_CONTROL, RequestResult.NOT_ALLOWED)
    rig.request(S.COMM_ENABLED)
    rig.run(0.02)
    s = rig.last("LocomotionStatus")
    assert (s["State"], s["RequestResult"]) == (S.COMM_ENABLED, RequestResult.ACCEPTED)


def test_raw_actuator_commands_only_in_test_mode() -> None:
    rig = Rig()
    rig.stand()
    cmd = CODEC.encode("HipCommand", {"Position": 0.3, "Velocity": 0.0, "Kp": 20.0, "Kd": 0.5,
                                      "Torque": 0.0})
    hip = rig.lower.body.actuators[0]
    before = hip.command
    rig.lower.receive(0, 1, cmd)
    assert hip.command == before and rig.lower.stats["rx_actuator_command_refused"] == 1
    rig.request(S.SITDOWN_MODE)
    rig.run(1.2)
    rig.request(S.IN_TEST_MODE)
    rig.run(0.01)
    assert rig.lower.body.state is S.IN_TEST_MODE
    rig.frames.clear()
    rig.run(0.01)
    assert not any(i in COMMAND_MESSAGES for _, _, i, _ in rig.frames)  # the upper side's turn
    for _ in range(1500):
        rig.lower.receive(0, 1, cmd)
        rig.run(0.001)
    assert hip.reported_position == pytest.approx(0.3, abs=0.02)
    replies = [d for _, b, i, d in rig.frames if b == 0 and i == REPLY_ID]
    assert len(replies) == 1500 and all(d[0] == 1 for d in replies)  # each answered at once
    rig.lower.receive(0, 1, special_frame(Special.EXIT_MOTOR_MODE))
    assert not hip.motor_mode


def test_velocity_watchdog() -> None:
    rig = Rig()
    rig.stand()
    rig.request(S.IN_CONTROL)
    rig.run(1.0, (1.0, 0.0, 0.0))
    assert rig.last("BaseVelocity")["Vx"] == pytest.approx(1.0, abs=1e-3)
    timeout = rig.profile.body.command_timeout
    rig.run(timeout - 0.05)  # silence, but still fresh: keeps walking
    assert rig.lower.body.v[0] == pytest.approx(1.0)
    rig.run(0.1 + 1.0 / rig.profile.body.accel)  # stale: ramps down at the accel limit
    assert rig.lower.body.v[0] == 0.0 and rig.lower.body.state is S.IN_CONTROL
    assert rig.lower.stats["velocity_command_timeouts"] == 1


def test_walking_moves_the_reported_base() -> None:
    rig = Rig()
    rig.stand()
    rig.request(S.IN_CONTROL)
    rig.run(3.0, (0.5, 0.0, 0.0))
    s = rig.last("BasePosition")
    b = rig.lower.body
    rig.run(0.001)  # tick 0 mod 20: BasePosition of this very step
    s = rig.last("BasePosition")
    assert s["X"] == pytest.approx(b.x, abs=1e-3) and s["Y"] == pytest.approx(b.y, abs=1e-3)
    assert 1.3 < b.x < 1.5  # 3 s at 0.5 m/s, less the 0.25 s ramp's 0.0625 m


def test_body_temperature_closed_form() -> None:
    # the model alone, any step size: T(t) = Ta + P R (1 - exp(-t / RC))
    th = BodyThermal(3000.0, 0.8, 25.0)
    t = 0.0
    for dt in (0.001, 0.5, 13.0, 200.0, 0.25):
        th.step(dt, 40.0)
        t += dt
        assert th.temperature == pytest.approx(25.0 + 32.0 * (1 - math.exp(-t / 2400.0)),
                                               rel=1e-12)
    # in the lower computer lying down (no motor loss): the electronics' idle_current x V
    rig = Rig(bms=False)
    rig.run(5.0)
    p = rig.profile
    power = p.battery.idle_current_a * p.battery.nominal_voltage_v
    tau = p.thermal.body_thermal_mass * p.thermal.body_thermal_resistance
    want = 25.0 + power * p.thermal.body_thermal_resistance * (1 - math.exp(-5.0 / tau))
    assert rig.lower.thermal.temperature == pytest.approx(want, rel=1e-9)
    assert rig.last("BodyTemperature")["Body"] == pytest.approx(want, abs=0.05)


def test_bms_frames_decode_with_the_wheeled_accumulator() -> None:
    rig = Rig(soc=64.0)
    rig.stand()
    rig.request(S.IN_CONTROL)
    rig.run(3.0, (1.0, 0.0, 0.0))
    rig.run(0.001)  # tick 0 mod 1000: a poll and the five Bms* frames of it
    acc = BmsFrameAccumulator()
    for _, bus, fid, data in rig.frames:
        if bus == 0 and fid >= 0x300:
            acc.update(*CODEC.decode(fid, data))
    snap = acc.snapshot()
    truth = rig.lower.bms_snapshot
    assert snap is not None and truth is not None
    assert snap.voltage == pytest.approx(truth.voltage, abs=0.006)
    assert snap.current == pytest.approx(truth.current, abs=0.006)
    assert snap.soc == math.floor(truth.soc) and snap.capacity_design == 6.0
    # walking draws more than the electronics alone, and it comes out of the pack
    assert truth.current < -rig.profile.battery.idle_current_a - 0.5
    assert truth.soc < 64.0


def _hot_profile() -> LeggedProfile:
    p = LeggedProfile()
    return replace(p, thermal=replace(p.thermal, body_thermal_mass=10.0, body_fault_c=40.0,
                                      body_clear_c=30.0))


def test_body_over_temperature_sits_down_then_damps() -> None:
    rig = Rig(_hot_profile(), bms=False)
    rig.stand()
    b = rig.lower.body
    while not b.fault and rig.clock.now() < 40.0:
        rig.run(0.001)
    assert rig.lower.thermal.temperature == pytest.approx(40.0, abs=0.01)
    assert b.fault == Fault.BODY_OVER_TEMPERATURE and b.state is S.SITDOWN_MODE
    rig.run(1.2)
    assert b.state is S.MOTOR_DISABLED and b.height == pytest.approx(0.10)
    assert rig.last("LocomotionStatus")["Fault"] == Fault.BODY_OVER_TEMPERATURE
    rig.request(S.MOTOR_READY)  # still hot (the electronics keep it above body_clear_c)
    assert b.result is RequestResult.FAULTED and b.state is S.MOTOR_DISABLED
    rig.lower.thermal.temperature = 25.0  # cooled
    rig.request(S.MOTOR_READY)
    assert b.result is RequestResult.ACCEPTED and not b.fault


def test_battery_protection_at_critical_soc() -> None:
    rig = Rig(soc=3.0)
    rig.run(0.02)
    assert rig.last("LocomotionStatus")["Fault"] == Fault.BATTERY_PROTECTION
    rig.request(S.COMM_ENABLED)
    assert rig.lower.body.result is RequestResult.FAULTED
    rig.request(S.MOTOR_READY)
    assert rig.lower.body.result is RequestResult.FAULTED


def test_bad_input_is_counted_not_raised() -> None:
    rig = Rig()
    lower = rig.lower
    lower.receive(0, 0x010, b"\x01")  # short LocomotionRequest
    lower.receive(0, 0x020, b"\xff" * 7 + b"\xff")  # wrong length
    lower.receive(2, 0x010, b"\x01\x00")  # a body frame on a leg bus
    lower.receive(0, 0x7FF, b"")  # not in the catalog
    lower.receive(7, 1, b"\x00" * 8)  # no such bus (refused before: not in test mode)
    lower.body.state = S.IN_TEST_MODE
    lower.receive(7, 1, b"\x00" * 8)
    lower.receive(0, 2, b"\x00" * 3)
    assert lower.stats["rx_malformed"] == 3 and lower.stats["rx_wrong_bus"] == 2
    assert lower.stats["rx_ignored"] == 1 and lower.stats["rx_actuator_command_refused"] == 1
    assert lower.stats["rx_frames"] == 7
