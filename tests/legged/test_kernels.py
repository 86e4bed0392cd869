"""The compiled 1 ms period (lowerbase.legged.kernels) against gait.py's Python kinematics and
the codec: joint targets, gravity loads, stance, power sums, the 24 actuator frames, and the
errors it reports instead of raising inside compiled code."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.clock import SimClock
from lowerbase.errors import EncodeError
from lowerbase.legged.body import FRONT, SIDES, Body
from lowerbase.legged.figures import BODY, mini_cheetah
from lowerbase.legged.gait import KinematicsError, leg_fk, leg_ik
from lowerbase.legged.lower import LeggedLower
from lowerbase.legged.profile import LeggedProfile
from lowerbase.protocol.legged import (
    JOINT_NAMES,
    KD_MAX,
    KP_MAX,
    P_MAX,
    REPLY_ID,
    REPLY_PREFIX,
    T_MAX,
    V_MAX,
    LocomotionState,
    joint_address,
    legged_codec,
    parse_special,
)

S = LocomotionState
DT = 0.001


def _walking(seconds: float) -> Body:
    body = mini_cheetah()
    for target in (S.COMM_ENABLED, S.MOTOR_READY, S.MOTOR_ENABLED):
        body.request(target)
    for _ in range(round((BODY.commutation_time + 0.01) / DT)):
        body.step(DT)
    body.request(S.STANDING_MODE)
    for _ in range(round((BODY.stand_time + 0.1) / DT)):
        body.step(DT)
    body.request(S.IN_CONTROL)
    for _ in range(round(seconds / DT)):
        body.velocity_command(0.6, 0.1, 0.4)
        body.step(DT)
    return body


def _expected(body: Body) -> tuple[list[float], list[float], list[bool]]:
    """Joint targets, loads and stance of the step just done, from gait.py (Python)."""
    g, p = body.g, body.p
    vx, vy, wz = body.v
    feet, stance = [], []
    for leg in range(4):
        hx, hy = FRONT[leg] * g.hip_x, SIDES[leg] * g.hip_y
        dx, dy, z, st = body.trot.foot(leg, body._gait_t, (vx - wz * hy, vy + wz * hx),
                                       body.height)
        feet.append((dx, dy, z))
        stance.append(st)
    weight = p.mass * p.gravity / max(sum(stance), 1)
    q_des, loads = [], []
    for leg in range(4):
        side = SIDES[leg]
        q = leg_ik(feet[leg][0], side * g.abad_link + feet[leg][1], feet[leg][2], side, g)
        q_des += q
        force = weight if stance[leg] else 0.0
        base = leg_fk(q, side, g)[2]
        for j in range(3):
            qq = list(q)
            qq[j] += 1e-6
            dz = (leg_fk((qq[0], qq[1], qq[2]), side, g)[2] - base) / 1e-6
            loads.append(-force * dz if force else 0.0)
    return q_des, loads, stance


def test_trotting_targets_loads_and_stance_are_gait_pys_to_the_bit() -> None:
    body = _walking(0.7)
    for _ in range(5):  # a few periods, each checked against the Python kinematics
        body.velocity_command(0.6, 0.1, 0.4)
        body.step(DT)
        q_des, loads, stance = _expected(body)
        assert body.stance == stance
        assert 0 < sum(stance) < 4  # mid-trot: a diagonal pair in stance
        for i, a in enumerate(body.actuators):
            assert a.command == (q_des[i], 0.0, BODY.kp, BODY.kd, -loads[i]), JOINT_NAMES[i]


def test_power_sums_are_the_actuators_copper_loss_and_draw() -> None:
    body = _walking(0.5)
    losses = [1.5 * a.params.phase_resistance * a.current() ** 2 for a in body.actuators]
    draw = sum(a.torque * a.velocity for a in body.actuators) + sum(losses)
    assert body.power[0] == pytest.approx(sum(losses), rel=1e-12) and sum(losses) > 0
    assert body.power[1] == pytest.approx(draw, rel=1e-12)


def test_a_foot_out_of_reach_is_a_kinematics_error_naming_the_leg() -> None:
    body = _walking(0.1)
    body.height = 1.0  # legs of 0.21 + 0.21 m
    with pytest.raises(KinematicsError, match=r"^FR foot .* out of the leg's reach"):
        body.step(DT)


class _Wire:
    def __init__(self) -> None:
        self.frames: list[tuple[int, int, bytes]] = []

    def send(self, bus: int, frame_id: int, data: bytes) -> None:
        self.frames.append((bus, frame_id, bytes(data)))


def _clamp(x: float, hi: float, lo: float) -> float:
    return min(max(x, lo), hi)


def test_the_24_frames_are_the_codecs_encoding_of_the_actuators() -> None:
    wire, clock = _Wire(), SimClock()
    lower = LeggedLower(LeggedProfile(), clock, wire.send)
    lower.body = _walking(0.4)
    lower._wire_state = S.IN_CONTROL
    wire.frames.clear()
    lower.step()
    codec = legged_codec()
    actuator = wire.frames[:24]
    for i, a in enumerate(lower.body.actuators):
        bus, mid = joint_address(i)
        cmd, reply = actuator[2 * i], actuator[2 * i + 1]
        assert cmd[:2] == (bus, mid) and reply[:2] == (bus, REPLY_ID)
        p, v, kp, kd, tau = a.command
        assert cmd[2] == codec.encode(codec.message(mid).name, {
            "Position": _clamp(p, P_MAX, -P_MAX), "Velocity": _clamp(v, V_MAX, -V_MAX),
            "Kp": _clamp(kp, KP_MAX, 0.0), "Kd": _clamp(kd, KD_MAX, 0.0),
            "Torque": _clamp(tau, T_MAX[mid], -T_MAX[mid])})
        pre = REPLY_PREFIX[mid]
        assert reply[2] == codec.encode("MotorReply", {
            "MotorId": mid, f"{pre}Position": _clamp(a.reported_position, P_MAX, -P_MAX),
            f"{pre}Velocity": _clamp(a.velocity, V_MAX, -V_MAX),
            f"{pre}Torque": _clamp(a.torque, T_MAX[mid], -T_MAX[mid]),
            "Temperature": round(a.temperature), "Error": 0})


def test_leaving_motor_mode_sends_exit_frames_answered_by_replies() -> None:
    wire, clock = _Wire(), SimClock()
    lower = LeggedLower(LeggedProfile(), clock, wire.send)
    lower.body = _walking(0.1)
    lower._wire_state = S.IN_CONTROL
    lower.request(int(S.MOTOR_DISABLED))
    wire.frames.clear()
    lower.step()
    cmds = wire.frames[:24:2]
    assert all(parse_special(d) is not None and d[7] == 0xFD for _, _, d in cmds)
    assert [f[1] for f in wire.frames[1:24:2]] == [REPLY_ID] * 12


def test_a_broken_actuator_state_is_an_encode_error_naming_the_joint() -> None:
    wire, clock = _Wire(), SimClock()
    lower = LeggedLower(LeggedProfile(), clock, wire.send)
    lower.body = _walking(0.1)
    lower._wire_state = S.IN_CONTROL
    lower.body.bank.command[4, 0] = math.nan  # FL_thigh's target
    with pytest.raises(EncodeError, match="FL_thigh's command does not encode"):
        lower._actuator_traffic()
    assert np.isnan(lower.body.bank.command[4, 0])
