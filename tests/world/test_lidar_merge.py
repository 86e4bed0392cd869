"""ScanMerger.merge with its per-beam constants computed once: bit for bit the per-scan merge."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pytest

from lowerbase.world.lidar import (
    TWO_PI,
    LaserScan,
    LidarConfig,
    LidarRig,
    MergedScanConfig,
    ScanMerger,
)
from lowerbase.world.sim import WorldConfig, WorldSim
from tests.world.lidar_reference import reference_merge


def merge_per_scan(merger: ScanMerger, scans: Sequence[LaserScan], stamp: float) -> np.ndarray:
    """The merge as it was before its constants were cached: the reference merge's ranges."""
    return reference_merge(merger, scans, stamp).ranges


def same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_merged_warehouse_scans_are_bit_identical_to_the_per_scan_merge() -> None:
    world = WorldSim(WorldConfig(map="warehouse", start="start"))
    rig = world.rig
    x0, y0, yaw0 = world.true_pose()
    rng = np.random.default_rng(3)
    for k in range(12):
        pose = (x0 + rng.uniform(-0.3, 0.3), y0 + rng.uniform(-0.3, 0.3),
                yaw0 + rng.uniform(-math.pi, math.pi))
        scans = rig.scans(world.scene, pose, 0.04 * k)
        assert same(rig.merger.merge(scans, 0.04 * k).ranges,
                    merge_per_scan(rig.merger, scans, 0.04 * k))


@pytest.mark.parametrize("merged", [
    MergedScanConfig(),
    MergedScanConfig(beams=360, angle_min=-1.0, fov=math.radians(200)),
    MergedScanConfig(beams=1000, angle_min=0.5, fov=TWO_PI),
])
def test_non_finite_returns_and_partial_merges_match_the_per_scan_merge(
        merged: MergedScanConfig) -> None:
    front = LidarConfig(name="front", frame_id="f", x=0.34, y=0.24, yaw=math.radians(45),
                        range_max=8.0, range_min=0.1)
    back = replace(front, name="back", frame_id="b", x=-0.34, y=-0.24, yaw=math.radians(-135),
                   fov=math.radians(180), seed=2)
    rig = LidarRig([front, back], merged)
    rng = np.random.default_rng(11)
    for stamp in range(8):
        scans = []
        for lc in (front, back):
            r = rng.uniform(0.1, 8.0, lc.beams)
            pick = rng.random(lc.beams)
            r[pick < 0.1] = np.inf
            r[(pick >= 0.1) & (pick < 0.15)] = -np.inf
            r[(pick >= 0.15) & (pick < 0.2)] = np.nan
            scans.append(LaserScan(lc.frame_id, stamp, lc.angle_min,
                                   lc.angle_min + (lc.beams - 1) * lc.angular_step,
                                   lc.angular_step, 0.0, 0.04, lc.range_min, lc.range_max,
                                   r.astype(np.float32)))
        got = rig.merger.merge(scans, float(stamp)).ranges
        assert same(got, merge_per_scan(rig.merger, scans, float(stamp)))
    # all finite (the fast path) and a changed beam count (the constants rebuilt)
    short = replace(scans[0], ranges=np.full(100, 2.0, np.float32))
    for pair in ([short, scans[1]], scans):
        assert same(rig.merger.merge(pair, 0.0).ranges, merge_per_scan(rig.merger, pair, 0.0))
