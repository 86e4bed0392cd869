"""The rig's batched scan against the per-lidar path it replaced, bit for bit.

:meth:`LidarRig.scans` casts every lidar's rays in one ``cast_grid`` call and
:meth:`ScanMerger.merge` bins all lidars' beams at once. ``reference_scan`` below is the rig as
it was before (each lidar cast alone through ``Lidar.true_ranges``, then merged lidar by lidar,
the merge kept verbatim): both must give the same /scan, float for float, including noise,
dropouts, -inf/+inf/NaN, solids and poses near walls and off the map.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from lowerbase.world.lidar import LaserScan, LidarConfig, LidarRig
from lowerbase.world.maps import load_map
from lowerbase.world.raycast import Scene, Solid
from lowerbase.world.sensors import SensorsConfig
from tests.world.lidar_reference import reference_merge


def reference_scan(rig: LidarRig, scene: Scene, pose: tuple[float, float, float],
                   stamp: float) -> LaserScan:
    """Each lidar cast alone, then the per-lidar merge."""
    scans = [lidar.scan(scene, pose, stamp) for lidar in rig.lidars]
    return reference_merge(rig.merger, scans, stamp)


def _same(a: LaserScan, b: LaserScan) -> None:
    assert a.ranges.dtype == b.ranges.dtype
    np.testing.assert_array_equal(a.ranges, b.ranges)  # NaN == NaN here, -0 vs 0 too
    assert np.array_equal(np.signbit(a.ranges), np.signbit(b.ranges))
    assert (a.angle_min, a.angle_increment, a.range_min, a.range_max, a.stamp) == \
        (b.angle_min, b.angle_increment, b.range_min, b.range_max, b.stamp)


def _lidars(dropout: float, range_max: float) -> list[LidarConfig]:
    return [replace(lc, dropout_prob=dropout, range_max=range_max, range_min=0.3)
            for lc in SensorsConfig().lidars]


@pytest.mark.parametrize(("dropout", "range_max"), [(0.0, 40.0), (0.05, 40.0), (0.02, 3.0)])
def test_the_batched_scan_is_the_per_lidar_scan(dropout: float, range_max: float) -> None:
    grid = load_map("warehouse")
    scene = Scene(grid)
    crate = Solid(1.0, np.array([[5.0, 1.6], [5.6, 1.6], [5.6, 2.3], [5.0, 2.3]]))
    person = Solid(1.7, circle=(7.0, 2.4, 0.25))
    low = Solid(0.1, circle=(6.0, 1.5, 0.3))  # under the scan plane: not seen
    with_solids = scene.with_solids([crate, person, low])
    lidars = _lidars(dropout, range_max)
    batched, reference = LidarRig(lidars), LidarRig(lidars)
    rng = np.random.default_rng(3)
    w, h = grid.size_m
    ox, oy, _ = grid.origin
    poses = [(4.0 + 0.05 * k, 2.0, 0.1 * k) for k in range(20)]
    poses += [(float(ox + rng.uniform(-1.0, w + 1.0)), float(oy + rng.uniform(-1.0, h + 1.0)),
               float(rng.uniform(-math.pi, math.pi))) for _ in range(40)]  # walls, off the map
    for k, pose in enumerate(poses):
        sc = with_solids if k % 2 else scene
        _same(batched.scan(sc, pose, 0.04 * k), reference_scan(reference, sc, pose, 0.04 * k))


def test_a_rig_standing_still_scans_as_a_fresh_one() -> None:
    """The rig keeps its last map cast for the same grid and pose (bit for bit): standing,
    turning by one ulp, -0.0 for 0.0, solids coming and going and another map give the scans
    the rig without that cast gives, noise and all."""
    grid = load_map("warehouse")
    other = Scene(load_map("warehouse"))  # another grid: cast again
    scene = Scene(grid)
    person = scene.with_solids([Solid(1.7, circle=(5.0, 2.4, 0.25))])
    lidars = _lidars(0.05, 40.0)
    kept, fresh = LidarRig(lidars), LidarRig(lidars)
    still = (4.0, 2.0, 0.0)
    poses = [still, still, (4.0, 2.0, -0.0), still, (4.0, 2.0, math.nextafter(0.0, 1.0)),
             still, still, (4.5, 2.0, 0.3), (4.5, 2.0, 0.3), still]
    scenes = [scene, scene, scene, person, scene, other, other, scene, person, scene]
    for k, (pose, sc) in enumerate(zip(poses, scenes, strict=True)):
        draws = fresh.draw()
        fresh._last_cast = None
        _same(kept.scan(sc, pose, 0.04 * k, draws), fresh.scan(sc, pose, 0.04 * k, draws))
        dist = kept.grid_distance(sc, pose)
        assert not dist.flags.writeable
        np.testing.assert_array_equal(dist, LidarRig(lidars).grid_distance(sc, pose))
