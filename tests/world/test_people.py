"""People wait for a standing robot (issue 22 item 24): one record, read by contact and sensors.

In the field trial people walked through a standing robot (0.196 m^2 overlap for 1.3 s): a
person was a function of time alone. Now a person whose next step would come within
``CLEARANCE`` of the footprint waits (lowerbase/world/people.py); the waits live in the
world's :class:`~lowerbase.world.obstacles.Obstacles`, which the emulator's contact and the
lidars both read, so the scan shows the person where contact has it. Simulated clock only.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from lowerbase.driver.core import LinkState
from lowerbase.world.localization.poses import compose
from lowerbase.world.obstacles import Obstacles, Person
from lowerbase.world.people import CLEARANCE, STEP, Crowd
from lowerbase.world.sim import WorldConfig, WorldSim

START = (5.0, 4.0, 0.0)  # empty_room's start; the footprint spans y = 3.7 .. 4.3 there
WALKER = Person("walker", path=((5.0, 1.0), (5.0, 7.0)), speed=1.2)  # straight through it


def test_a_person_crossing_a_standing_robot_waits_and_the_scan_sees_it_there() -> None:
    w = WorldSim(WorldConfig(map="empty_room", start=START, obstacles=Obstacles([WALKER]),
                             localization="off"))
    overlap = 0.0
    stood = True

    def watch(s: WorldSim) -> None:
        nonlocal overlap, stood
        foot = s.config.footprint.at(s.true_pose())
        shape = dict(s.obstacles.shapes_at(s.now))["walker"]
        overlap = max(overlap, foot.intersection(shape).area)
        stood = stood and s.loop.mcu.truth.x == 0.0 and s.loop.mcu.truth.y == 0.0

    w.run(8.0, on_step=watch)  # standing: the person would have passed it after 3.6 s
    assert w.loop.driver.state == LinkState.READY
    assert stood and overlap == 0.0
    assert w.contact is None and not w.contact_events
    # it waits on its path, CLEARANCE short of the footprint's edge (y = 3.7), within one
    # grid step's walk; on time alone it would be at y = 7 (the path's end)
    x, y = w.obstacles.position(WALKER, w.now)
    edge = 4.0 - 0.3 - WALKER.radius - CLEARANCE
    assert x == 5.0 and edge - WALKER.speed * STEP <= y <= edge + 1e-9
    assert WALKER.position_at(w.now) == (5.0, 7.0)
    # the last scan (its own stamp) has returns on the person's circle where it waits
    scan = w.scan
    assert scan is not None
    px, py = w.obstacles.position(WALKER, scan.stamp)
    assert (px, py) == (x, y)
    ok = np.isfinite(scan.ranges)
    r, a = scan.ranges[ok].astype(np.float64), scan.angles[ok]
    ends = [compose(w.true_pose(), (float(ri * math.cos(ai)), float(ri * math.sin(ai)), 0.0))
            for ri, ai in zip(r, a, strict=True)]
    gaps = np.array([math.hypot(ex - px, ey - py) - WALKER.radius for ex, ey, _ in ends])
    on_person = np.abs(gaps) < 0.05  # range noise 12 mm
    assert on_person.sum() >= 5


def test_a_person_walks_on_when_the_robot_leaves() -> None:
    """It waits while the robot stands in its way, then goes on from where it stood: never a
    step longer than its walk (no jump to where time alone would put it)."""
    w = WorldSim(WorldConfig(map="empty_room", start=START, obstacles=Obstacles([WALKER]),
                             localization="off"))
    last = w.obstacles.position(WALKER, w.now)
    longest = 0.0

    def watch(s: WorldSim) -> None:
        nonlocal last, longest
        now = s.obstacles.position(WALKER, s.now)
        longest = max(longest, math.hypot(now[0] - last[0], now[1] - last[1]))
        last = now

    w.run(5.0, on_step=watch)
    assert w.obstacles.crowd.waited("walker", w.now) > 1.0
    w.drive(0.5, 0.0, 3.0, on_step=watch)  # east, out of its way
    cleared = w.obstacles.crowd.waited("walker", w.now)
    w.run(2.0, on_step=watch)
    assert w.obstacles.crowd.waited("walker", w.now) == cleared  # it walks on
    x, y = w.obstacles.position(WALKER, w.now)
    assert x == 5.0 and y > 4.3  # past the robot's old place
    assert y == pytest.approx(WALKER.position_at(w.now - cleared)[1])
    assert longest <= WALKER.speed * w.control_dt + 1e-9
    assert not w.contact_events


def test_waits_are_exact_at_any_decided_time() -> None:
    """Blocked on the grid steps that start in (1.0, 1.5]: it waits those 0.5 s, and its
    waited time at any instant is the part of them before it."""
    crowd = Crowd(("p",))
    crowd.advance(0.0, lambda name, t: False)
    crowd.advance(1.0, lambda name, t: False)
    crowd.advance(1.5, lambda name, t: True)
    assert crowd.waits["p"].since == pytest.approx(1.0 + STEP)  # still waiting
    crowd.advance(3.0, lambda name, t: False)
    assert crowd.waits["p"].since is None
    assert crowd.decided_until == pytest.approx(3.0 + STEP)
    for t, waited in ((0.5, 0.0), (1.02, 0.0), (1.27, 0.25), (1.52, 0.5), (2.5, 0.5)):
        assert crowd.waited("p", t) == pytest.approx(waited)


def test_two_processes_reading_the_truth_at_different_rates_agree_on_a_standing_robot() -> None:
    """The real-time split: the emulator's contact decides the waits every control period
    (5 ms), the world node from every truth sample its receiver takes (20 ms, on a grid of its
    own: here offset by 13 ms), through ``PeopleFromTruth`` chained after the receiver's hook;
    with the robot standing both put the person at the same place at every time."""
    from lowerbase.world.maps import load_map
    from lowerbase.world.truth import PeopleFromTruth, TruthSample, WorldSurroundings

    class Receiver:  # what TruthReceiver offers: on_sample, called with every new sample
        def __init__(self) -> None:
            self.on_sample: Callable[[TruthSample], None] | None = seen.append

    seen: list[TruthSample] = []
    grid = load_map("empty_room")
    emulator = WorldSurroundings(grid, Obstacles([WALKER]), map_from_truth=START)
    receiver = Receiver()
    world = PeopleFromTruth(WorldSurroundings(grid, Obstacles([WALKER]), map_from_truth=START),
                            receiver)
    assert world.each_sample
    here = (0.0, 0.0, 0.0)  # the emulator's frame: the robot at its start
    for k in range(1, 1601):  # 8 s
        t = k * 0.005
        emulator.allowed(here, here, t)
        if k % 4 == 0:
            sample = TruthSample(t - 0.007, *here, 0.0, 0.0, False)
            assert receiver.on_sample is not None
            receiver.on_sample(sample)
            people = world.surroundings.obstacles
            assert people.position(WALKER, sample.t) == \
                emulator.obstacles.position(WALKER, sample.t)
    assert len(seen) == 400  # the hook already there still gets every sample
    assert emulator.obstacles.crowd.waited("walker", 8.0) > 4.0


def test_replacing_the_obstacles_keeps_the_waits_of_who_stays() -> None:
    from lowerbase.world.obstacles import Box

    obs = Obstacles([WALKER])
    obs.crowd.advance(0.0, lambda name, t: False)
    obs.crowd.advance(1.0, lambda name, t: True)
    waited = obs.crowd.waited("walker", 1.0)
    assert waited > 0.9
    other = Person("other", path=((1.0, 1.0), (2.0, 1.0)))
    obs.replace([WALKER, other, Box("crate", (3.0, 3.0), (0.4, 0.4))])
    assert obs.crowd.waited("walker", 1.0) == waited
    assert obs.crowd.waited("other", 1.0) == 0.0
    assert obs.crowd.decided_until == pytest.approx(1.0 + STEP)
    assert obs.people == (WALKER, other)
    assert obs.fresh().crowd.waited("walker", 1.0) == 0.0
