"""WorldSim.run_periods (the emulator and driver batched between the world's events) against
WorldSim.step period by period: the same bits for what the world shows (true pose, /odom,
the localization estimate, the merged scan, contacts), driving through the warehouse with
turns, past a box, into a wall and standing, with amcl and its scans (update_min_d) on."""

from __future__ import annotations

import math

import numpy as np

from lowerbase.simloop.loop import SimLoop
from lowerbase.world.obstacles import Box, Obstacles
from lowerbase.world.sim import WorldConfig, WorldSim

#: (linear, angular, seconds) at 20 Hz
SCRIPT = [(0.0, 0.0, 1.5), (0.6, 0.0, 3.0), (0.5, 0.6, 2.0), (0.8, -0.3, 3.0), (0.0, 0.9, 2.0),
          (0.7, 0.0, 6.0), (-0.3, 0.0, 1.0), (0.0, 0.0, 2.0), (1.0, 0.2, 4.0)]


def _world() -> WorldSim:
    config = WorldConfig(map="warehouse", start="start",
                         obstacles=Obstacles([Box("crate", center=(2.0, 0.0), size=(0.5, 0.5))]))
    world = WorldSim(config, loop=SimLoop(soc=60.0))
    x, y, yaw = world.start
    crate = (x + 2.5 * math.cos(yaw), y + 2.5 * math.sin(yaw))
    world.obstacles.items = Obstacles([Box("crate", center=crate, size=(0.5, 0.5))]).items
    return world


def _state(w: WorldSim) -> tuple[object, ...]:
    scan = w.scan
    return (w.now, w.true_pose(), w.odom_pose(), w.amcl_pose(), w.contact,
            None if scan is None else scan.ranges.tobytes(), w.scans)


def test_batched_periods_give_the_stepped_world() -> None:
    stepped, batched = _world(), _world()
    every = round(0.05 / stepped.control_dt)
    contacts = [0, 0]
    for linear, angular, seconds in SCRIPT:
        for _ in range(round(seconds / 0.05)):
            for w in (stepped, batched):
                w.loop.driver.set_twist(linear, angular)
            for _ in range(every):
                stepped.step()
                contacts[0] += stepped.contact is not None
            contacts[1] += batched.run_periods(every)
            assert _state(stepped) == _state(batched)
    assert contacts[0] == contacts[1]
    assert stepped.contact_events == batched.contact_events
    assert stepped.localizer.stats == batched.localizer.stats
    assert batched.loop.batch_stats["batches"] > 100  # batching happened
    assert batched.gate.skipped > 0 and np.isfinite(batched.true_pose()[0])
