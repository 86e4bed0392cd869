"""Step control on the simulated clock through the real chain: SimLoop (emulator + driver_base
core) driven at 20 Hz via driver.set_twist, closed loop on /odom (the driver's EKF pose)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.bench.simloop import SimLoop
from lowerbase.navigation.controller import Limits, wrap
from lowerbase.navigation.steps import (
    CANCEL,
    CANCELLED,
    DIAGONALIZE,
    EXCUTE,
    LATERAL,
    PAUSE,
    REJECTED,
    RESUM,
    ROTATE,
    STRAIGHT,
    SUCCEEDED,
    Step,
    StepController,
)


def _loop() -> tuple[SimLoop, StepController]:
    loop = SimLoop()
    loop.run(1.0)
    return loop, StepController(Limits.from_parameters(loop.driver.parameters))


def _odom(loop: SimLoop) -> tuple[float, float, float]:
    x, y, yaw = loop.driver.ekf.pose
    return float(x), float(y), float(yaw)


def _run(loop: SimLoop, ctl: StepController, timeout: float,
         until: float | None = None) -> None:
    end = loop.now + timeout
    while loop.now < end and (ctl.active if until is None else loop.now < until):
        v, w = ctl.tick(_odom(loop))
        loop.driver.set_twist(v, w)
        for _ in range(10):
            loop.step()
    loop.drive(0.0, 0.0, 0.5)


def test_random_steps_within_1cm_and_half_a_degree_on_odom() -> None:
    rng = np.random.default_rng(3)
    loop, ctl = _loop()
    for _ in range(6):
        before = _odom(loop)
        if rng.random() < 0.5:
            dist = float(rng.uniform(-1.5, 1.5))
            speed = float(rng.choice([0.0, 0.3, 0.5]))
            assert ctl.goal(EXCUTE, [Step(STRAIGHT, dist, speed)]) is None
            _run(loop, ctl, timeout=30.0)
            after = _odom(loop)
            moved = (after[0] - before[0]) * math.cos(before[2]) + \
                (after[1] - before[1]) * math.sin(before[2])
            lateral = -(after[0] - before[0]) * math.sin(before[2]) + \
                (after[1] - before[1]) * math.cos(before[2])
            assert abs(moved - dist) <= 0.01 and abs(lateral) <= 0.01
            assert abs(wrap(after[2] - before[2])) <= math.radians(0.5)
        else:
            angle = float(rng.uniform(-4.0, 4.0))
            speed = float(rng.choice([0.0, 0.3, 0.8]))
            assert ctl.goal(EXCUTE, [Step(ROTATE, angle, speed)]) is None
            _run(loop, ctl, timeout=90.0)
            after = _odom(loop)
            assert abs(wrap(after[2] - before[2] - angle)) <= math.radians(0.5)
            assert math.hypot(after[0] - before[0], after[1] - before[1]) <= 0.01
        assert ctl.result is not None and ctl.result.result == SUCCEEDED
        assert ctl.result.percent == 100.0


def test_a_list_runs_in_order_and_the_truth_follows() -> None:
    loop, ctl = _loop()
    t0 = loop.mcu.truth
    start = (t0.x, t0.y, t0.yaw)
    steps = [Step(STRAIGHT, 1.0, 0.4), Step(ROTATE, math.pi / 2, 0.5), Step(STRAIGHT, 0.5),
             Step(ROTATE, -2 * math.pi - math.pi / 2, 0.6)]  # more than a full turn
    assert ctl.goal(EXCUTE, steps) is None
    _run(loop, ctl, timeout=200.0)
    assert ctl.result is not None and ctl.result.result == SUCCEEDED
    x, y, yaw = _odom(loop)
    assert (x, y) == pytest.approx((1.0, 0.5), abs=0.02)
    assert abs(wrap(yaw)) <= math.radians(1.0)
    tr = loop.mcu.truth  # the emulator's ground truth agrees within odometry error
    assert math.hypot(tr.x - start[0] - 1.0, tr.y - start[1] - 0.5) <= 0.05


def test_default_speeds_are_02_and_01() -> None:
    loop, ctl = _loop()
    ctl.goal(EXCUTE, [Step(STRAIGHT, 1.0)])
    _run(loop, ctl, timeout=3.0, until=loop.now + 3.0)
    assert loop.driver.odometry is not None
    assert max(abs(ctl.v), 0.0) == pytest.approx(0.2, abs=1e-9)
    ctl.goal(CANCEL)
    _run(loop, ctl, timeout=2.0, until=loop.now + 2.0)
    ctl.goal(EXCUTE, [Step(ROTATE, 1.0)])
    _run(loop, ctl, timeout=3.0, until=loop.now + 3.0)
    assert ctl.w == pytest.approx(0.1, abs=1e-9)


def test_pause_resume_cancel() -> None:
    loop, ctl = _loop()
    ctl.goal(EXCUTE, [Step(STRAIGHT, 2.0, 0.4)])
    _run(loop, ctl, timeout=2.5, until=loop.now + 2.5)
    ctl.goal(PAUSE)
    _run(loop, ctl, timeout=2.0, until=loop.now + 2.0)
    held = _odom(loop)
    assert ctl.feedback is not None and ctl.feedback.feedback == 2
    assert 0 < ctl.feedback.percent < 100
    _run(loop, ctl, timeout=2.0, until=loop.now + 2.0)
    assert math.hypot(_odom(loop)[0] - held[0], _odom(loop)[1] - held[1]) < 1e-3
    ctl.goal(RESUM)
    _run(loop, ctl, timeout=30.0)
    assert ctl.result is not None and ctl.result.result == SUCCEEDED
    assert _odom(loop)[0] == pytest.approx(2.0, abs=0.01)
    ctl.goal(EXCUTE, [Step(STRAIGHT, 3.0, 0.4)])
    _run(loop, ctl, timeout=2.0, until=loop.now + 2.0)
    ctl.goal(CANCEL)
    assert ctl.result is not None and ctl.result.result == CANCELLED
    assert 0 < ctl.result.percent < 100
    _run(loop, ctl, timeout=2.0, until=loop.now + 2.0)
    assert abs(loop.mcu.truth.v) < 1e-3


@pytest.mark.parametrize("steps, why", [
    ([], "empty"),
    ([Step(STRAIGHT, float("nan"))], "finite"),
    ([Step(ROTATE, 1.0, float("inf"))], "finite"),
    ([Step(STRAIGHT, 10.5)], "10"),
    ([Step(ROTATE, -63.0)], "62.8318"),
    ([Step(STRAIGHT, 1.0, -0.1)], "speed"),
    ([Step(STRAIGHT, 1.0, 5.0)], "speed"),
    ([Step(STRAIGHT, 1.0), Step(LATERAL, 0.5)], "differential"),
    ([Step(DIAGONALIZE, 0.5, 0.1, 0.3)], "differential"),
    ([Step(7, 0.5)], "executeMode 7"),
])
def test_refused_goals_leave_the_robot_still(steps: list[Step], why: str) -> None:
    loop, ctl = _loop()
    before = (loop.mcu.truth.x, loop.mcu.truth.y, loop.mcu.truth.yaw)
    answer = ctl.goal(EXCUTE, steps)
    assert answer is not None and answer.result == REJECTED and why in answer.message
    _run(loop, ctl, timeout=3.0, until=loop.now + 3.0)
    assert not ctl.active
    tr = loop.mcu.truth
    assert (tr.x, tr.y, tr.yaw) == before
    assert ctl.goal(9) is not None  # an unknown mode: rejected too


def test_use_avoid_waits_while_blocked() -> None:
    loop, ctl = _loop()
    blocked = {"on": True}
    ctl.obstacle_ahead = lambda pose, v, w: blocked["on"]
    ctl.goal(EXCUTE, [Step(STRAIGHT, 0.5)], use_avoid=True)
    _run(loop, ctl, timeout=3.0, until=loop.now + 3.0)
    assert ctl.feedback is not None and ctl.feedback.feedback == 3
    assert abs(loop.mcu.truth.x) < 1e-3
    blocked["on"] = False
    _run(loop, ctl, timeout=20.0)
    assert ctl.result is not None and ctl.result.result == SUCCEEDED
