"""The compiled lidar noise (scan_kernel.measure) against Lidar.measure's numpy, bit for bit:
true distances at and around range_min / range_max, none (inf), zero, with and without
dropouts and range-dependent noise."""

from __future__ import annotations

import numpy as np
import pytest

from lowerbase.world.lidar import Lidar, LidarConfig
from lowerbase.world.scan_kernel import measure


@pytest.mark.parametrize(("sigma_per_m", "dropout"), [(0.0, 0.0), (0.01, 0.0), (0.002, 0.1)])
def test_measure_is_lidar_measure(sigma_per_m: float, dropout: float) -> None:
    cfg = LidarConfig(range_min=0.1, range_max=8.0, range_sigma=0.02,
                      range_sigma_per_m=sigma_per_m, dropout_prob=dropout, seed=5)
    lidar = Lidar(cfg)
    rng = np.random.default_rng(2)
    n = cfg.beams
    edges = np.array([0.0, 0.1, np.nextafter(0.1, 0.0), np.nextafter(0.1, 1.0), 8.0,
                      np.nextafter(8.0, 9.0), 7.99, 0.05, np.inf, 3.0])
    for _ in range(5):
        true = rng.uniform(0.0, 9.0, n)
        true[rng.random(n) < 0.2] = np.inf
        true[:edges.size] = edges
        normal, uniform = lidar.draw()
        want = lidar.measure(true, (normal, uniform))
        got = np.empty(n, dtype=np.float32)
        measure(true, normal, uniform if uniform is not None else normal, uniform is not None,
                cfg.range_sigma, cfg.range_sigma_per_m, cfg.range_min, cfg.range_max,
                cfg.dropout_prob, got)
        assert got.tobytes() == want.tobytes()
