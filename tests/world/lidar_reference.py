"""ScanMerger.merge as it was before batching (lidar by lidar): the reference the batched merge
and its cached per-beam constants are compared with, bit for bit."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from lowerbase.world.lidar import LaserScan, ScanMerger

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
