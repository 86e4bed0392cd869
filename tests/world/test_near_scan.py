"""LidarRig.near_scan against the full scan with the same random numbers, and WorldSim.near_scan
leaving every scan (this tick's full one included) bit for bit what it was (as
:meth:`WorldSim.skip_scan`, it takes the tick's noise)."""

from __future__ import annotations

import numpy as np
import pytest

from lowerbase.world.lidar import NearScan
from lowerbase.world.maps import load_map
from lowerbase.world.raycast import Scene, Solid
from lowerbase.world.sim import WorldConfig, WorldSim

POSES = [(4.0, 2.0, 0.0), (10.0, 2.0, 0.5), (15.0, 10.0, 1.0), (8.0, 6.0, 2.0), (2.0, 9.0, -2.5)]


@pytest.mark.parametrize("reach", [1.0, 3.01, 6.0])
def test_near_scan_is_the_full_scan_below_reach(reach: float) -> None:
    world = WorldSim(WorldConfig(map="warehouse", start="start", localization="off"))
    grid = load_map("warehouse")
    person = Solid(1.8, circle=(10.8, 2.4, 0.25))
    crate = Solid(0.5, polygon=np.array([[3.2, 9.3], [3.6, 9.3], [3.6, 9.7], [3.2, 9.7]]))
    scene = Scene(grid, (person, crate))
    seen = [0, 0]
    for pose in POSES:
        draws = world.rig.draw()
        full = world.rig.scan(scene, pose, 0.0, draws).ranges.astype(float)
        near = world.rig.near_scan(scene, pose, 0.0, draws, reach)
        assert isinstance(near, NearScan)
        r = near.ranges.astype(float)
        below = r < reach
        seen[0] += int(below.sum())
        seen[1] += int((near.unknown | (r >= reach)).sum())
        assert np.array_equal(r[below], full[below])                # exact
        far = np.isfinite(r) & ~below
        assert (full[far] >= reach).all() and (full[far] < near.range_max).all()
        assert np.isnan(r[near.unknown]).all()
        unknown_full = full[near.unknown]
        assert not (np.isfinite(unknown_full) & (unknown_full < reach)).any()
        assert np.array_equal(np.isfinite(r) | near.unknown, np.isfinite(full) | near.unknown)
    assert seen[0] > 0 and seen[1] > 0


def test_world_near_scan_leaves_every_scan_as_it_was() -> None:
    def run(near: bool) -> list[np.ndarray]:
        world = WorldSim(WorldConfig(map="warehouse", start="start", localization="off"))
        out = []
        for k in range(12):
            world.run(0.04)
            if near and k % 3 == 0:
                n = world.near_scan(3.01)
                assert isinstance(n, NearScan) and n.full is not None
                if k % 2 == 0:
                    out.append(n.full().ranges)
                    continue
            elif k % 3 == 0:
                world.skip_scan()  # the reference: the tick's noise drawn, nothing cast
            if k % 2 == 0:
                scan = world.scan
                assert scan is not None
                out.append(scan.ranges)
        return out

    ref, new = run(False), run(True)
    assert len(ref) == len(new) == 6
    for a, b in zip(ref, new, strict=True):
        assert np.array_equal(a, b, equal_nan=True)
