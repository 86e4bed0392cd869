"""Contact through the firmware model's Surroundings seam: the emulated robot stops at walls,
boxes and people, in both control loops, and the world says what it touched.

Closed forms: the footprint is convex, so its furthest reach along +x at pose (x, y, yaw) is the
largest of its vertices' x + px cos(yaw) - py sin(yaw); driving towards a wall face at x = X
stops the robot with that reach in [X - one step of travel, X] (the move that would overlap is
refused, the robot stays put). The true robot curves slightly (its wheel radii differ by the
profile's [truth] errors), hence the yaw.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Point

from lowerbase.driver.core import LinkState
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.simloop.loop import SimLoop
from lowerbase.world.footprint import DEFAULT_FOOTPRINT
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.obstacles import Box, Obstacles, Person
from lowerbase.world.people import CLEARANCE, STEP
from lowerbase.world.truth import LoopTruth, WorldSurroundings

RES = 0.05
WALL_X = 6.0  # [m] the face of the wall column


def room() -> OccupancyGrid:
    """10 x 10 m free floor with a wall column whose face is at x = WALL_X."""
    data = np.zeros((200, 200), np.int8)
    data[:, round(WALL_X / RES)] = 100
    return OccupancyGrid(data, RES)


def reach_x(x: float, yaw: float) -> float:
    """The footprint's furthest x at (x, yaw)."""
    return max(x + px * math.cos(yaw) - py * math.sin(yaw) for px, py in DEFAULT_FOOTPRINT.points)


def ready(loop: SimLoop) -> bool:
    return loop.driver.state == LinkState.READY and loop.mcu.state.name == "ACTIVE"


def loop_with(world: WorldSurroundings) -> SimLoop:
    loop = SimLoop(bms=None, surroundings=world)
    assert loop.run_until(ready, timeout=3.0)
    return loop


@pytest.fixture(params=[True, False], ids=["lean", "hooked"])
def control_loop(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> bool:
    monkeypatch.setattr(Mcu, "lean", request.param)
    return bool(request.param)


def test_driving_into_a_wall_stops_at_the_wall(control_loop: bool) -> None:
    world = WorldSurroundings(room(), map_from_truth=(3.0, 5.0, 0.0))
    loop = loop_with(world)
    speed = 0.5
    loop.drive(speed, 0.0, 8.0)  # 4 m needed, only 2.6 m free
    truth = loop.mcu.truth
    step = 1.1 * speed * loop.mcu.dt
    assert WALL_X - step <= reach_x(3.0 + truth.x, truth.yaw) <= WALL_X
    assert abs(truth.yaw) < 0.02
    assert truth.blocked and truth.v == 0.0 and truth.w == 0.0
    assert world.contact is not None and world.contact.touched == ("wall",)
    assert world.contact.point[0] == pytest.approx(WALL_X, abs=step + 1e-6)
    assert [e.touched for e in world.events] == [("wall",)]
    # the default profile's motors overpower the traction (test_blocked_traction.py): the
    # wheels slip on against the wall and /odom believes it drove on
    odom_x = loop.driver.ekf.pose[0]
    assert odom_x > truth.x + 0.5
    sample = LoopTruth(loop).sample()
    assert sample.contact and sample.v == 0.0 and sample.x == truth.x


def test_backing_off_the_wall_is_free(control_loop: bool) -> None:
    world = WorldSurroundings(room(), map_from_truth=(3.0, 5.0, 0.0))
    loop = loop_with(world)
    loop.drive(0.5, 0.0, 7.0)
    at_wall = loop.mcu.truth.x
    loop.drive(-0.3, 0.0, 2.0)
    loop.run(1.0)
    truth = loop.mcu.truth
    assert not truth.blocked and world.contact is None
    assert truth.x < at_wall - 0.3
    assert world.events[-1].end is not None  # the contact ended


def test_a_box_stops_the_robot_and_is_named() -> None:
    box = Box("crate", center=(5.0, 5.0), size=(0.4, 1.2))  # near face at x = 4.8
    world = WorldSurroundings(room(), Obstacles([box]), map_from_truth=(2.0, 5.0, 0.0))
    loop = loop_with(world)
    loop.drive(0.4, 0.0, 10.0)
    truth = loop.mcu.truth
    assert 4.8 - 1.1 * 0.4 * loop.mcu.dt <= reach_x(2.0 + truth.x, truth.yaw) <= 4.8
    assert world.contact is not None and world.contact.touched == ("crate",)


def test_a_person_walking_into_the_way_stops_the_robot(control_loop: bool) -> None:
    # the person walks down from y = 9 and stops at (4.0, 5.0), in the robot's lane by t = 4 s;
    # the robot, at 0.3 m/s from x = 1, reaches it later: its front meets the circle at 3.75
    person = Person("walker", path=((4.0, 9.0), (4.0, 5.0)), speed=1.0, radius=0.25)
    world = WorldSurroundings(room(), Obstacles([person]), map_from_truth=(1.0, 5.0, 0.0))
    loop = loop_with(world)
    loop.drive(0.3, 0.0, 14.0)
    truth = loop.mcu.truth
    # the gap between the footprint and the person's centre: the radius, plus at most one
    # step (the refused move would have overlapped); the circle is a 64-gon, within 0.3 mm of r
    gap = DEFAULT_FOOTPRINT.at((1.0 + truth.x, 5.0 + truth.y, truth.yaw)).distance(
        Point(4.0, 5.0))
    assert 0.25 - 3e-4 <= gap <= 0.25 + 1.1 * 0.3 * loop.mcu.dt
    assert loop.mcu.truth.blocked
    assert world.contact is not None and world.contact.touched == ("walker",)
    assert world.events[0].start > 4.0


def test_a_person_walking_at_a_standing_robot_stops_short_of_it() -> None:
    # the person's path runs straight through where the robot stands, from t = 0: it waits
    # CLEARANCE short of the footprint (issue 22 item 24: it walked through, 0.196 m^2 overlap)
    person = Person("walker", path=((5.0, 2.0), (5.0, 8.0)), speed=1.0, radius=0.25)
    world = WorldSurroundings(room(), Obstacles([person]), map_from_truth=(5.0, 5.0, 0.0))
    loop = loop_with(world)
    loop.run(8.0 - loop.now)
    assert (loop.mcu.truth.x, loop.mcu.truth.y) == (0.0, 0.0)
    assert not world.events and world.contact is None  # never touched
    # the footprint's back edge is y = 5 - 0.3: the centre waits CLEARANCE + r short of it,
    # within one grid step's walk (decided on the STEP grid, at the step's end)
    x, y = world.obstacles.position(person, loop.now)
    assert x == 5.0
    assert 5.0 - 0.3 - 0.25 - CLEARANCE - 1.0 * STEP <= y <= 5.0 - 0.3 - 0.25 - CLEARANCE + 1e-9
    assert world.obstacles.crowd.waited("walker", loop.now) > 4.0


def test_turning_in_place_next_to_a_wall_is_blocked_by_the_corners() -> None:
    # base 0.45 m from the wall face: the front edge (0.4) clears it, the circumscribed
    # circle (0.473) does not: turning by a few degrees brings a corner into the wall
    world = WorldSurroundings(room(), map_from_truth=(WALL_X - 0.45, 5.0, 0.0))
    loop = loop_with(world)
    loop.drive(0.0, 0.5, 3.0)
    truth = loop.mcu.truth
    # corner (0.4, 0.253) rotated by yaw reaches x = 0.4 cos - 0.253 sin... the front-left
    # corner region (0.353, 0.3)/(0.4, 0.253) first touches the face at 0.45: solve exactly
    yaws = np.linspace(0.0, 0.6, 60001)
    reach = np.max([px * np.cos(yaws) - py * np.sin(yaws)
                    for px, py in ((0.4, -0.253), (0.353, -0.3))], axis=0)
    first = float(yaws[np.argmax(reach > 0.45)])
    assert first - 0.5 * loop.mcu.dt - 1e-4 <= truth.yaw <= first
    assert truth.blocked


def test_nothing_installed_means_open_floor() -> None:
    loop = SimLoop(bms=None)
    assert loop.surroundings is None
    assert loop.run_until(ready, timeout=3.0)
    loop.drive(0.5, 0.0, 3.0)
    assert not loop.mcu.truth.blocked and loop.mcu.truth.blocked_steps == 0
    assert loop.mcu.truth.x > 1.0


def test_clearance_shortcut_agrees_with_the_polygon_test() -> None:
    rng = np.random.default_rng(3)
    box = Box("crate", center=(3.0, 3.0), size=(0.5, 0.5), yaw=0.3)
    person = Person("p", path=((1.0, 1.0), (8.0, 8.0)), speed=0.5)
    world = WorldSurroundings(room(), Obstacles([box, person]))
    from lowerbase.world.footprint import contact

    for _ in range(600):
        pose = (float(rng.uniform(-0.5, 10.5)), float(rng.uniform(-0.5, 10.5)),
                float(rng.uniform(-math.pi, math.pi)))
        t = float(rng.uniform(0, 20))
        assert world.touching(pose, t) == contact(pose, world.grid, world.obstacles, t)
    assert 0 < world.checks < 600
