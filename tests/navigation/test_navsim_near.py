"""NavSim's local costmap from near scans (cast only as far as the costmap reads) against the
full scans (``near_scans=False``, the reference): tick by tick the same true poses, estimates,
commands and obstacle layers on a drive past a person and a crate; and LayeredCostmap.update
from a NearScan equals the update from its full scan with stale marks everywhere (so that the
fallback to the full scan is taken too)."""

from __future__ import annotations

import numpy as np

from lowerbase.navigation.costmap import local_costmap
from lowerbase.navigation.layers import LETHAL_OBSTACLE
from lowerbase.navigation.sim import NavSim
from lowerbase.world.lidar import NearScan
from lowerbase.world.obstacles import Box
from lowerbase.world.raycast import Scene, Solid
from lowerbase.world.sim import WorldConfig, WorldSim


def drive(near: bool) -> tuple[list[tuple[object, ...]], NavSim]:
    world = WorldSim(WorldConfig(map="warehouse", start="start"))
    world.run(1.0)
    sim = NavSim(world, near_scans=near)
    sim.set_obstacles([Box("crate", (7.0, 2.6), (0.4, 0.4))])
    trace: list[tuple[object, ...]] = []

    def during(ns: NavSim, _: object) -> None:
        layer = ns.navigator.local_costmap.obstacle_layer
        assert layer is not None
        trace.append((world.true_pose(), world.amcl_pose(), ns.last, layer.map.origin,
                      layer.map.data.tobytes()))

    sim.go_to((10.0, 2.0, 0.0), timeout=60.0, during=during)
    return trace, sim


def test_drive_with_near_scans_is_the_drive_with_full_scans() -> None:
    ref, _ = drive(False)
    new, sim = drive(True)
    assert len(new) == len(ref) > 100
    assert new == ref
    stats = sim.navigator.local_costmap.stats
    assert sim.world.near_scans == stats.near_scans > 0


def test_costmap_update_from_a_near_scan_is_that_of_its_full_scan() -> None:
    world = WorldSim(WorldConfig(map="warehouse", start="start", localization="off"))
    scene = Scene(world.grid, (Solid(1.8, circle=(10.8, 2.4, 0.25)),))
    rng = np.random.default_rng(3)
    fallbacks = 0
    for pose in [(4.0, 2.0, 0.0), (10.0, 2.0, 0.5), (15.0, 10.0, 1.0), (8.0, 6.0, 2.0)]:
        for stale in (0.0, 0.002, 0.05):
            ref, new = local_costmap(world.grid, pose), local_costmap(world.grid, pose)
            marks = rng.random(ref.map.data.shape) < stale
            for cm in (ref, new):
                assert cm.obstacle_layer is not None
                cm.obstacle_layer.map.data[marks] = LETHAL_OBSTACLE
            draws = world.rig.draw()
            full = world.rig.scan(scene, pose, 0.0, draws)
            near = world.rig.near_scan(scene, pose, 0.0, draws, new.scan_reach,
                                       full=lambda full=full: full)  # type: ignore[misc]
            assert isinstance(near, NearScan)
            ref.update(pose, full)
            new.update(pose, near)
            assert np.array_equal(new.costs, ref.costs)
            fallbacks += new.stats.near_full
    assert fallbacks > 0
