"""The body controller: every row of the transition table, stand-walk-sit on the simulated
clock with the feet consistent with the base motion, over-temperature -> sit -> damped."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from lowerbase.legged.body import ALLOWED, Body
from lowerbase.legged.figures import BODY, mini_cheetah
from lowerbase.protocol.legged import Fault, LocomotionState, RequestResult

S = LocomotionState
DT = 0.001


def _run(body: Body, seconds: float, cmd: tuple[float, float, float] | None = None) -> None:
    for _ in range(round(seconds / DT)):
        if cmd is not None:
            body.velocity_command(*cmd)
        body.step(DT)


def _in_state(state: LocomotionState) -> Body:
    body = mini_cheetah()
    body.state = state
    if state in (S.STANDING_MODE, S.IN_CONTROL):
        body.height = BODY.stand_height  # standing finished
    return body


@pytest.mark.parametrize("state", list(S))
@pytest.mark.parametrize("target", list(S))
def test_transition_table_row(state: LocomotionState, target: LocomotionState) -> None:
    body = _in_state(state)
    result = body.request(int(target))
    busy = state in (S.SITDOWN_MODE, S.MOTOR_COMMUTATION) and target is not S.MOTOR_DISABLED
    if busy:
        assert result is RequestResult.BUSY
        assert body.state is state
    elif target in ALLOWED[state]:
        assert result is RequestResult.ACCEPTED
        expected = S.MOTOR_COMMUTATION if target is S.MOTOR_ENABLED and state in (
            S.MOTOR_READY, S.MOTOR_DISABLED) else target
        assert body.state is expected
    else:
        assert result is RequestResult.NOT_ALLOWED
        assert body.state is state


def test_unknown_request_is_refused() -> None:
    body = mini_cheetah()
    assert body.request(12) is RequestResult.NOT_ALLOWED
    assert body.state is S.COMM_DISABLED


def _stand(body: Body) -> None:
    for target in (S.COMM_ENABLED, S.MOTOR_READY, S.MOTOR_ENABLED):
        assert body.request(target) is RequestResult.ACCEPTED
    assert body.state is S.MOTOR_COMMUTATION
    _run(body, BODY.commutation_time + 0.01)
    assert body.state is S.MOTOR_ENABLED
    assert body.request(S.STANDING_MODE) is RequestResult.ACCEPTED
    assert body.request(S.IN_CONTROL) is RequestResult.BUSY  # still standing up
    _run(body, BODY.stand_time + 0.5)
    assert body.height == pytest.approx(BODY.stand_height)


def test_stand_walk_sit_feet_follow_the_base() -> None:
    body = mini_cheetah()
    _stand(body)
    for leg in range(4):  # standing: feet on the ground below the hips
        assert abs(body.foot_world(leg)[2]) < 2e-3
    assert body.request(S.IN_CONTROL) is RequestResult.ACCEPTED
    _run(body, 1.0, (0.5, 0.0, 0.0))  # accelerate to 0.5 m/s
    assert body.v[0] == pytest.approx(0.5)
    x0 = body.x
    planted: dict[int, tuple[float, float]] = {}
    worst = 0.0
    for _ in range(400):  # one gait period at constant velocity
        body.velocity_command(0.5, 0.0, 0.0)
        body.step(DT)
        for leg in range(4):
            fx, fy, fz = body.foot_world(leg)
            if body.stance[leg]:
                assert abs(fz) < 0.015  # PD tracking under the switching load
                ref = planted.setdefault(leg, (fx, fy))
                worst = max(worst, math.hypot(fx - ref[0], fy - ref[1]))
            else:
                planted.pop(leg, None)
    assert worst < 0.02  # stance feet stay put (PD tracking error only)
    assert body.x - x0 == pytest.approx(0.5 * 0.4, rel=1e-6)
    assert body.request(S.STANDING_MODE) is RequestResult.ACCEPTED
    assert body.request(S.SITDOWN_MODE) is RequestResult.ACCEPTED
    _run(body, BODY.stand_time + 0.01)
    assert body.state is S.MOTOR_ENABLED
    assert body.height == pytest.approx(BODY.sit_height)


def test_turning_keeps_the_quaternion_and_pose_consistent() -> None:
    body = mini_cheetah()
    _stand(body)
    body.request(S.IN_CONTROL)
    _run(body, 3.0, (0.0, 0.0, 1.0))
    x, y, z, w = body.quaternion()
    assert 2 * math.atan2(z, w) == pytest.approx(body.yaw)
    assert x == y == 0.0 and z * z + w * w == pytest.approx(1.0)


def test_over_temperature_sits_down_then_damps() -> None:
    body = mini_cheetah()
    _stand(body)
    for a in body.actuators:  # a small, poorly cooled motor from here on
        a.params = replace(a.params, thermal_time_constant=2.0, thermal_resistance=40.0,
                           derate_c=35.0, fault_c=40.0, clear_c=30.0)
    body.request(S.IN_CONTROL)
    t = 0.0
    while not body.fault and t < 60:
        _run(body, 0.1, (0.8, 0.0, 0.0))
        t += 0.1
    assert body.fault & Fault.ACTUATOR_OVER_TEMPERATURE
    assert 0 <= body.fault_joint < 12
    assert body.state is S.SITDOWN_MODE
    assert body.request(S.STANDING_MODE) is RequestResult.FAULTED
    _run(body, BODY.stand_time + 0.01)
    assert body.state is S.MOTOR_DISABLED
    assert body.height == pytest.approx(BODY.sit_height)
    assert body.request(S.MOTOR_READY) is RequestResult.FAULTED  # still hot
    _run(body, 30.0)
    assert body.request(S.MOTOR_READY) is RequestResult.ACCEPTED
    assert not body.fault
