"""The contact gate: the world's surroundings are left out of a control period only where the
robot provably touches nothing, so the robot drives the same bits with or without the gate.

- ``free_space`` is a sound bound: every point within its slack (and, for people, within what
  they can walk) passes the cheap clearance test, checked against that test on random poses
  and moves (the test the surroundings run first; it finds nothing wherever the polygon test
  finds nothing, test_contact.py).
- End to end: a WorldSim driving into a wall, a box dropped in its lane while the gate has the
  surroundings out, and a person walking into it: gate on and gate off give the same true pose
  at every period, the same contact events and the same frames on the bus.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.bench.simloop import SimLoop
from lowerbase.world.obstacles import Box, Obstacles, Person
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


def _drive(gate: bool) -> tuple[WorldSim, list[tuple[float, float, float]], list[object]]:
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
            assert not w.surroundings._may_touch(w.true_pose(), w.now)

    world.run(2.0, record)
    world.drive(0.5, 0.0, 12.0, on_step=record)  # into the wall at x = 6: stopped there
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
    on, poses_on, frames_on = _drive(True)
    off, poses_off, frames_off = _drive(False)
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
    assert on.surroundings.checks == off.surroundings.checks


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
