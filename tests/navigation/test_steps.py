"""Step control on the simulated clock through the real chain: SimLoop (emulator + driver_base
core) driven at 20 Hz via driver.set_twist, closed loop on /odom (the driver's EKF pose)."""

from __future__ import annotations

import math
import re
from collections.abc import Callable

import numpy as np
import pytest

from lowerbase.navigation.controller import Limits, wrap
from lowerbase.navigation.steps import (
    CANCEL,
    CANCELLED,
    DIAGONALIZE,
    EXCUTE,
    FAILED,
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
from lowerbase.simloop.loop import SimLoop


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


# -- a plain kinematic robot on a simulated clock (issue 22 item 13) ------------------------------
class _Robot:
    """Integrates the commanded twist exactly, 20 Hz; ``deadband``: speeds below it do not move
    the robot (m/s, rad/s); ``wall``: x it cannot pass (a rack)."""

    def __init__(self, ctl: StepController) -> None:
        self.ctl, self.t = ctl, 0.0
        self.x = self.y = self.yaw = 0.0
        self.deadband = (0.0, 0.0)
        self.wall = math.inf
        self.commands: list[tuple[float, float]] = []

    def tick(self) -> None:
        v, w = self.ctl.tick((self.x, self.y, self.yaw), self.t)
        self.commands.append((v, w))
        v = v if abs(v) >= self.deadband[0] else 0.0
        w = w if abs(w) >= self.deadband[1] else 0.0
        self.x = min(self.x + v * math.cos(self.yaw) * 0.05, self.wall)
        self.y += v * math.sin(self.yaw) * 0.05
        self.yaw = wrap(self.yaw + w * 0.05)
        self.t += 0.05

    def run(self, seconds: float, until: Callable[[], bool] | None = None) -> None:
        end = self.t + seconds
        while self.t < end and self.ctl.active and not (until is not None and until()):
            self.tick()


def _left_off_at_the_stop(robot: _Robot, straight: float, angle: float) -> None:
    """At the step's first stop, the robot stands ``straight`` m short / ``angle`` rad short of
    the target (a slip), and from then on corrections are too slow to move it (a deadband)."""
    ctl = robot.ctl
    robot.tick()  # the step starts
    robot.run(60.0, until=lambda: ctl.phase == "settle")
    assert ctl.active and ctl.phase == "settle"
    if straight:
        robot.x = 0.5 - straight
    if angle:
        robot.yaw = 1.0 - angle
    robot.deadband = (0.05, 0.2)  # above creep (0.03 m/s) and creep_rotation (0.1 rad/s)


def test_a_step_ending_a_little_off_is_done_and_the_list_goes_on() -> None:
    """12 mm / 0.8 deg left after the corrections: within accept_tolerance (2 cm) / accept_angle
    (1 deg) the step is finished and the next one runs (it used to end the list with -3)."""
    ctl = StepController(period=0.05)
    robot = _Robot(ctl)
    assert ctl.goal(EXCUTE, [Step(STRAIGHT, 0.5), Step(ROTATE, 1.0, 0.5)]) is None
    _left_off_at_the_stop(robot, 0.012, 0.0)
    robot.run(30.0, until=lambda: ctl.mode == ROTATE)
    assert ctl.active and ctl.mode == ROTATE
    assert ctl.summary.startswith("step 1 ended 12.0 mm off on /odom after 5 correction(s)")
    robot.deadband = (0.0, 0.0)
    _left_off_at_the_stop(robot, 0.0, math.radians(0.8))
    robot.run(30.0)
    assert ctl.result is not None and ctl.result.result == SUCCEEDED, ctl.result
    assert ctl.result.percent == 100.0 and "0.80 deg off" in ctl.result.message


def test_a_step_far_off_after_its_corrections_still_fails() -> None:
    ctl = StepController(period=0.05)
    robot = _Robot(ctl)
    assert ctl.goal(EXCUTE, [Step(STRAIGHT, 0.5), Step(ROTATE, 1.0)]) is None
    _left_off_at_the_stop(robot, 0.03, 0.0)
    robot.run(30.0)
    assert ctl.result is not None and ctl.result.result == FAILED
    assert ctl.result.message == "step 1: still 30.0 mm off after 5 corrections"
    assert ctl.result.execute_mode == STRAIGHT


def test_a_step_driven_into_a_rack_fails_after_the_stall_timeout() -> None:
    """No progress on /odom while driving: after stall_timeout (4 s) the list ends -3 with the
    reason and the command goes to zero, instead of pushing on (ACTIVE) for ever."""
    ctl = StepController(period=0.05)
    robot = _Robot(ctl)
    robot.wall = 0.6
    assert ctl.goal(EXCUTE, [Step(STRAIGHT, 1.5, 0.3), Step(ROTATE, 1.0)]) is None
    robot.run(10.0, until=lambda: robot.x >= 0.6)
    hit = robot.t
    robot.run(60.0)
    assert ctl.result is not None and ctl.result.result == FAILED
    assert 3.5 <= robot.t - hit <= 4.5
    assert re.fullmatch(r"step 1: no progress for 4 s while driving \(blocked or stalled\?\), "
                        r"900\.0 mm left", ctl.result.message), ctl.result.message
    assert 0 < ctl.result.percent < 50
    for _ in range(20):
        robot.tick()
    assert robot.commands[-1] == (0.0, 0.0)


def test_a_step_stalling_just_short_is_done_a_slow_or_waiting_one_is_no_stall() -> None:
    # a deadband stops the robot some mm short while braking: within the accept tolerance
    ctl = StepController(period=0.05, stall_timeout=2.0)
    robot = _Robot(ctl)
    robot.deadband = (0.06, 0.0)
    assert ctl.goal(EXCUTE, [Step(STRAIGHT, 0.5)]) is None
    robot.run(60.0)
    assert ctl.result is not None and ctl.result.result == SUCCEEDED, ctl.result
    assert 0.003 < 0.5 - robot.x < 0.02
    # a pause or an obstacle wait longer than stall_timeout, a very slow step: no stall
    ctl = StepController(period=0.05, stall_timeout=2.0)
    robot = _Robot(ctl)
    blocked = {"on": False}
    ctl.obstacle_ahead = lambda pose, v, w: blocked["on"]
    assert ctl.goal(EXCUTE, [Step(STRAIGHT, 0.3), Step(STRAIGHT, 0.01, 0.001)],
                    use_avoid=True) is None
    robot.run(0.5)
    ctl.goal(PAUSE)
    robot.run(5.0)
    ctl.goal(RESUM)
    blocked["on"] = True
    robot.run(5.0)
    assert ctl.active and ctl.feedback is not None and ctl.feedback.feedback == 3
    blocked["on"] = False
    robot.run(60.0)
    assert ctl.result is not None and ctl.result.result == SUCCEEDED, ctl.result
    assert robot.x == pytest.approx(0.31, abs=0.006), ctl.result


def test_resum_with_a_resent_list_replaces_the_remaining_steps() -> None:
    """The vendor: after a pause the remaining steps are sent again with RESUM. A different list
    replaces the paused step's rest and the steps after it, measured from where the robot
    stands; the unchanged remaining list continues the paused step."""
    ctl = StepController(period=0.05)
    robot = _Robot(ctl)
    assert ctl.goal(EXCUTE, [Step(STRAIGHT, 2.0, 0.4), Step(ROTATE, 1.0, 0.5)]) is None
    robot.run(3.0)
    ctl.goal(PAUSE)
    robot.run(2.0)
    held = robot.x
    assert 0.5 < held < 1.5
    assert ctl.goal(RESUM, [Step(STRAIGHT, 0.4, 0.3), Step(ROTATE, -0.5, 0.5)]) is None
    robot.run(60.0)
    assert ctl.result is not None and ctl.result.result == SUCCEEDED, ctl.result
    assert robot.x == pytest.approx(held + 0.4, abs=0.004)
    assert robot.yaw == pytest.approx(-0.5, abs=math.radians(0.2))
    # the same remaining list: the paused step goes on where it is (2 m in all)
    ctl = StepController(period=0.05)
    robot = _Robot(ctl)
    steps = [Step(STRAIGHT, 2.0, 0.4), Step(ROTATE, 1.0, 0.5)]
    assert ctl.goal(EXCUTE, steps) is None
    robot.run(3.0)
    ctl.goal(PAUSE)
    robot.run(2.0)
    assert ctl.goal(RESUM, list(steps)) is None
    robot.run(60.0)
    assert ctl.result is not None and ctl.result.result == SUCCEEDED, ctl.result
    assert robot.x == pytest.approx(2.0, abs=0.004)
    assert robot.yaw == pytest.approx(1.0, abs=math.radians(0.2))
    # a resent list that cannot run is refused; without a list RESUM just continues
    ctl = StepController(period=0.05)
    robot = _Robot(ctl)
    assert ctl.goal(EXCUTE, steps) is None
    robot.run(1.0)
    ctl.goal(PAUSE)
    refused = ctl.goal(RESUM, [Step(LATERAL, 0.5)])
    assert refused is not None and refused.result == REJECTED
    assert ctl.goal(RESUM) is None
    robot.run(60.0)
    assert robot.x == pytest.approx(2.0, abs=0.004)
