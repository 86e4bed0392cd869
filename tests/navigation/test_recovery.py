"""The back-off recovery on a hand-made cost grid: it backs off the way the robot came while
that stays clear, also when the footprint already touches a lethal cell ahead, and stops at its
distance or when the way back is blocked too."""

from __future__ import annotations

import numpy as np
import pytest

from lowerbase.navigation.planner import LETHAL, FootprintCells
from lowerbase.navigation.recovery import BackOff, BackOffConfig
from lowerbase.world.footprint import DEFAULT_POINTS

RES = 0.05


def grid(wall_x: list[float]) -> np.ndarray:
    costs = np.zeros((100, 100), np.uint8)  # 5 x 5 m, origin (0, 0)
    for x in wall_x:
        costs[:, int(x / RES)] = LETHAL
    return costs


FP = FootprintCells([tuple(map(float, p)) for p in DEFAULT_POINTS], RES)


def test_backs_off_from_a_wall_it_touches_and_stops_after_the_distance() -> None:
    costs = grid([2.8])  # the footprint's front (0.4 m) reaches it from x = 2.4
    pose = (2.4, 2.5, 0.0)
    assert FP.max_cost(costs, (0.0, 0.0), *pose)[0] >= LETHAL  # wedged
    b = BackOff(BackOffConfig(distance=0.3, speed=0.1))
    b.begin(pose, 0.0, reversed_driving=False)
    assert b.step(pose, 0.05, costs, (0.0, 0.0), FP) == pytest.approx(-0.1)
    assert b.step((2.25, 2.5, 0.0), 1.5, costs, (0.0, 0.0), FP) == pytest.approx(-0.1)
    assert b.step((2.09, 2.5, 0.0), 3.0, costs, (0.0, 0.0), FP) is None  # 0.31 m: done
    assert not b.active


def test_does_not_back_into_a_wall_behind() -> None:
    costs = grid([2.8, 1.85])
    b = BackOff()
    b.begin((2.4, 2.5, 0.0), 0.0, reversed_driving=False)
    assert b.step((2.4, 2.5, 0.0), 0.05, costs, (0.0, 0.0), FP) is None


def test_drives_forward_when_the_robot_was_reversing_and_gives_up_on_timeout() -> None:
    costs = grid([])
    b = BackOff(BackOffConfig(timeout=2.0))
    b.begin((2.5, 2.5, 0.0), 10.0, reversed_driving=True)
    assert b.step((2.5, 2.5, 0.0), 10.05, costs, (0.0, 0.0), FP) == pytest.approx(0.1)
    assert b.step((2.5, 2.5, 0.0), 12.0, costs, (0.0, 0.0), FP) is None  # wheels slipping
