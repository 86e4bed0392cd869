"""The rig's batched scan against the per-lidar path it replaced, bit for bit.

:meth:`LidarRig.scans` casts every lidar's rays in one ``cast_grid`` call and
:meth:`ScanMerger.merge` bins all lidars' beams at once. ``reference_scan`` below is the rig as
it was before (each lidar cast alone through ``Lidar.true_ranges``, then merged lidar by lidar,
the merge kept verbatim): both must give the same /scan, float for float, including noise,
dropouts, -inf/+inf/NaN, solids and poses near walls and off the map.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pytest

from lowerbase.world.lidar import LaserScan, LidarConfig, LidarRig, ScanMerger
from lowerbase.world.maps import load_map
from lowerbase.world.raycast import Scene, Solid
from lowerbase.world.sensors import SensorsConfig

TWO_PI = 2.0 * math.pi


def reference_merge(merger: ScanMerger, scans: Sequence[LaserScan], stamp: float) -> LaserScan:
    """ScanMerger.merge before batching (verbatim but for ``self``)."""
    m = merger.merged
    n = m.beams
    inc = m.increment
    best = np.full(n, np.inf)
    too_close = np.zeros(n, dtype=bool)
    clear = np.zeros(n, dtype=bool)
    for lc, scan in zip(merger.lidars, scans, strict=True):
        r = scan.ranges.astype(float)
        beam = scan.angles + lc.yaw
        finite = np.isfinite(r)
        reach = np.where(finite, r, np.where(r == np.inf, lc.range_max, lc.range_min))
        px = lc.x + reach * np.cos(beam)
        py = lc.y + reach * np.sin(beam)
        rel = np.arctan2(py, px) - m.angle_min
        idx = np.round(np.mod(rel, TWO_PI) / inc).astype(np.int64)
        if m.full_circle:
            idx %= n
        inside = (idx >= 0) & (idx < n)
        valid = inside & finite
        np.minimum.at(best, idx[valid], np.hypot(px[valid], py[valid]))
        too_close[idx[inside & (r == -np.inf)]] = True
        clear[idx[inside & (r == np.inf)]] = True
    out = np.where(np.isfinite(best), best,
                   np.where(too_close, -np.inf, np.where(clear, np.inf, np.nan)))
    period = 1.0 / merger.rate_hz
    return LaserScan(m.frame_id, stamp, m.angle_min, m.angle_min + (n - 1) * inc, inc,
                     period / n, period, merger.range_min, merger.range_max,
                     out.astype(np.float32))


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
