"""The contact gate: the world's surroundings are left out of a control period only where the
robot provably touches nothing, so the robot drives the same bits with or without the gate.

- ``free_space`` is a sound bound: every point within its slack (and, for people, within what
  they can walk) passes the cheap clearance test, checked against that test on random poses
  and moves (the test the surroundings run first; it finds nothing wherever the polygon test
  finds nothing, test_contact.py).
- ``polygon_free_space`` (a robot standing by a wall) is a sound bound on the polygon test,
  for moves and turns that use up its slack; one period moves no point of the footprint further
  than the gate's reach (the wheels at their limit: straight, spinning, turning).
- End to end: a WorldSim driving into a wall, standing a few cm from it, a box dropped in its
  lane while the gate has the surroundings out, and a person walking into it: gate on and gate
  off give the same true pose at every period, the same contact events and the same frames on
  the bus.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Point

from lowerbase.simloop.loop import SimLoop
from lowerbase.world.footprint import contact
from lowerbase.world.obstacles import Box, Obstacles, Person
from lowerbase.world.people import CLEARANCE, STEP
from lowerbase.world.sim import WorldConfig, WorldSim
from lowerbase.world.truth import WorldSurroundings
from tests.world.test_contact import room


def test_free_space_is_a_sound_bound_on_the_clearance_test() -> None:
    rng = np.random.default_rng(7)
    box = Box("crate", center=(3.0, 3.0), size=(0.5, 0.8), yaw=0.3)
    person = Person("p", path=((1.0, 8.0), (8.0, 1.0)), speed=0.8, loop=True)
    world = WorldSurroundings(room(), Obstacles([box, person]), map_from_truth=(0.5, 0.2, 0.1))
    roomy = 0
    for _ in range(400):
        pose = (float(rng.uniform(-1.0, 10.0)), float(rng.uniform(-1.0, 10.0)),
                float(rng.uniform(-math.pi, math.pi)))
        t = float(rng.uniform(0.0, 30.0))
        space = world.free_space(pose, t)
        assert space is not None
        static, moving, speed = space
        assert speed == 0.8
        if min(static, moving) <= 0.0:
            continue
        assert not world._may_touch(world.to_map(pose), t)
        roomy += static > 0.3
        for k in range(48):  # moves inside the slack, at times the people cannot use it up
            edge = k < 32  # to the edge of the slack, in 32 directions; then random ones
            d = (1.0 - 1e-9 if edge else float(rng.uniform(0.0, 1.0))) * min(static, moving)
            dt = float(rng.uniform(0.0, 1.0)) * max(moving - d, 0.0) / speed
            a = k * math.pi / 16 if edge else float(rng.uniform(-math.pi, math.pi))
            moved = (pose[0] + d * math.cos(a), pose[1] + d * math.sin(a), pose[2])
            assert not world._may_touch(world.to_map(moved), t + dt), (pose, t, d, a, dt)
    assert roomy > 50  # the bound is useful, not only safe


def test_polygon_free_space_is_a_sound_bound_on_the_polygon_test() -> None:
    rng = np.random.default_rng(11)
    box = Box("crate", center=(4.0, 5.0), size=(0.5, 0.8), yaw=0.3)
    person = Person("p", path=((5.0, 2.0), (5.0, 9.0)), speed=0.6, loop=True)
    world = WorldSurroundings(room(), Obstacles([box, person]))
    arm = world.footprint.radius
    roomy = 0
    for _ in range(300):  # poses near the wall at x = 6, the box, the person and the edge
        pose = (float(rng.uniform(0.2, 6.0)), float(rng.uniform(0.2, 9.8)),
                float(rng.uniform(-math.pi, math.pi)))
        t = float(rng.uniform(0.0, 20.0))
        space = world.polygon_free_space(pose, t)
        if space is None:
            assert contact(pose, world.grid, world.obstacles, t) is not None or \
                world.footprint.at(pose).distance(Point(5.0, 2.0 + (0.6 * t) % 7.0)) \
                < 0.25 + 1e-3 + CLEARANCE + 0.6 * STEP  # r + a 64-gon's error + a wait's reach
            continue
        static, moving, speed = space
        roomy += static > 0.05
        for k in range(16):  # a move and a turn that use up the slack (people: walking)
            d = (1.0 - 1e-9 if k % 2 else float(rng.uniform(0.0, 1.0))) * min(static, moving)
            share = float(rng.uniform(0.0, 1.0))
            a = float(rng.uniform(-math.pi, math.pi))
            turn = math.copysign((1.0 - share) * d / arm, float(rng.uniform(-1.0, 1.0)))
            dt = float(rng.uniform(0.0, 1.0)) * max(moving - d, 0.0) / speed
            moved = (pose[0] + share * d * math.cos(a), pose[1] + share * d * math.sin(a),
                     pose[2] + turn)
            assert contact(moved, world.grid, world.obstacles, t + dt) is None, (pose, t, k)
    assert roomy > 30


def _drive(gate: bool, near: list[int]
           ) -> tuple[WorldSim, list[tuple[float, float, float]], list[object]]:
    frames: list[object] = []
    person = Person("walker", path=((5.3, 9.0), (5.3, 5.38)), speed=1.0, radius=0.25,
                    start=22.0)
    world = WorldSim(WorldConfig(map=room(), start=(1.0, 5.0, 0.0), localization="off",
                                 obstacles=Obstacles([person])),
                     loop=SimLoop(bms=None, tap=lambda *f: frames.append(f)))
    world.gate.enabled = gate
    poses: list[tuple[float, float, float]] = []
    reach = [world.gate._reach()]

    def record(w: WorldSim) -> None:
        tr = w.loop.mcu.truth
        if poses:  # the gate's bound on one period's move holds
            assert math.hypot(tr.x - poses[-1][0], tr.y - poses[-1][1]) <= reach[-1]
        poses.append((tr.x, tr.y, tr.yaw))
        reach.append(w.gate._reach())
        if w.loop.surroundings is None:  # a period run without them: they had found nothing
            assert contact(w.true_pose(), w.grid, w.obstacles, w.now) is None

    world.run(2.0, record)
    world.drive(0.5, 0.0, 12.0, on_step=record)  # into the wall at x = 6: stopped there
    world.drive(-0.1, 0.0, 0.8, on_step=record)  # a few cm off it
    skipped = world.gate.skipped
    world.drive(0.0, 0.0, 2.0, on_step=record)   # standing by the wall: the footprint's slack
    near.append(world.gate.skipped - skipped)
    world.drive(-0.4, 0.0, 3.0, on_step=record)  # off it
    world.drive(0.0, 0.8, 2.0, on_step=record)   # about face
    # a box dropped 0.6 m ahead of the robot's front while it drives
    tr = world.loop.mcu.truth
    x, y, yaw = world.true_pose()
    ahead = (x + 1.1 * math.cos(yaw), y + 1.1 * math.sin(yaw))
    world.obstacles.items = Obstacles([person, Box("dropped", ahead, (0.2, 0.2))]).items
    world.drive(0.3, 0.0, 4.0, on_step=record)
    world.obstacles.items = Obstacles([person]).items
    world.drive(-0.3, 0.0, 1.0, on_step=record)
    world.drive(0.0, -0.8, 2.0, on_step=record)
    world.drive(0.4, 0.0, 8.0, on_step=record)  # the person stands in the lane at x = 5.3
    assert tr is world.loop.mcu.truth
    return world, poses, frames


def test_the_gate_changes_no_bit_of_the_drive() -> None:
    near: list[int] = []
    on, poses_on, frames_on = _drive(True, near)
    off, poses_off, frames_off = _drive(False, near)
    touched = [e.touched for e in on.contact_events]
    assert touched == [("wall",), ("wall",), ("dropped",), ("walker",)]
    assert [(e.start, e.end, e.touched, e.point) for e in on.contact_events] == \
        [(e.start, e.end, e.touched, e.point) for e in off.contact_events]
    assert poses_on == poses_off
    assert frames_on == frames_off
    assert on.loop.mcu.truth.blocked_steps == off.loop.mcu.truth.blocked_steps > 0
    # most periods ran without asking the world; none did in the reference
    assert off.gate.skipped == 0
    assert on.gate.skipped > 0.5 * len(poses_on)
    # standing a few cm from the wall (the circle's slack gone): out, on the footprint's own
    assert near[0] > 300 and near[1] == 0
    # the polygon tests the surroundings made and found nothing in, the gate skipped
    assert on.surroundings.checks < off.surroundings.checks


@pytest.mark.parametrize("what", ["slip", "contact"])
def test_the_surroundings_are_installed_when_the_bound_cannot_hold(what: str) -> None:
    from lowerbase.firmware_model.truth import SlipEvent

    world = WorldSim(WorldConfig(map=room(), start=(1.0, 5.0, 0.0), localization="off"),
                     loop=SimLoop(bms=None))
    world.run(1.0)
    assert world.loop.surroundings is None  # open floor: out
    if what == "slip":
        world.loop.mcu.slip.add_event(SlipEvent("left", world.now, 1.0, 0.5))
    else:
        world.obstacles.items = Obstacles([Box("b", (1.0, 5.0), (0.2, 0.2))]).items
    world.step()
    assert world.loop.surroundings is world.surroundings


@pytest.mark.parametrize("left, right", [(1.0, 1.0), (1.0, -1.0), (-1.0, 0.3), (0.0, -1.0)])
def test_one_period_moves_no_footprint_point_further_than_the_reach(left: float,
                                                                    right: float) -> None:
    # the wheels at their limit, forwards, spinning, turning: the truth's own step
    world = WorldSim(WorldConfig(map=room(), start=(3.0, 5.0, 0.4), localization="off"),
                     loop=SimLoop(bms=None))
    mcu = world.loop.mcu
    ml, mr = mcu.motors["left"], mcu.motors["right"]
    limit = max(ml.geometry.max_rpm / ml.geometry.ratio, mr.geometry.max_rpm / mr.geometry.ratio
                ) * 2.0 * math.pi / 60.0
    ml.omega, mr.omega = left * limit, right * limit
    arm = world.surroundings.footprint.radius
    reach, reach_arm = world.gate._reach(), world.gate._reach(arm)
    truth = mcu.truth
    before = world.surroundings.footprint.at(world.true_pose())
    x0, y0 = truth.x, truth.y
    truth.step(ml.omega, mr.omega, mcu.dt)
    after = world.surroundings.footprint.at(world.true_pose())
    moved = np.hypot(*(np.asarray(after.exterior.coords) - np.asarray(before.exterior.coords)).T)
    assert math.hypot(truth.x - x0, truth.y - y0) <= reach
    assert moved.max() <= reach_arm
    if left == -right:  # spinning in place at the limit: the turn's term is what bounds it
        assert moved.max() > 0.6 * reach_arm > reach
