"""FootprintCells.max_cost on uint8 costs runs the compiled gather (navigation.kernels); the numpy
batched gather it replaced is kept here as the reference: equal on random poses on, near and
off the map, every heading, scalars and 2D pose arrays, over costs with every cost class."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lowerbase.navigation.planner import LETHAL, NO_INFORMATION, FootprintCells
from lowerbase.world.footprint import DEFAULT_POINTS


def numpy_gather(fc: FootprintCells, costs: np.ndarray, origin: Sequence[float],
                 x: np.ndarray, y: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """The uint8 branch of max_cost before the kernel (all poses in one numpy gather)."""
    x, y, yaw = np.broadcast_arrays(np.atleast_1d(np.asarray(x, dtype=np.float64)),
                                    np.atleast_1d(np.asarray(y, dtype=np.float64)),
                                    np.atleast_1d(np.asarray(yaw, dtype=np.float64)))
    rows = np.floor((y - origin[1]) / fc.resolution).astype(np.int64)
    cols = np.floor((x - origin[0]) / fc.resolution).astype(np.int64)
    k = np.round(np.mod(yaw, 2.0 * np.pi) / (2.0 * np.pi) * fc.bins).astype(np.int64) % fc.bins
    h, w = costs.shape
    kk = k.ravel()
    r = rows.ravel()[:, None] + fc._dr[kk]
    c = cols.ravel()[:, None] + fc._dc[kk]
    off = ((r < 0) | (c < 0) | (r >= h) | (c >= w)).any(axis=1)
    np.clip(r, 0, h - 1, out=r)
    np.clip(c, 0, w - 1, out=c)
    vals = costs[r, c]
    vals[vals == NO_INFORMATION] = 0
    best = vals.max(axis=1).astype(np.int64)
    best[off] = LETHAL
    return best.reshape(x.shape)


def test_compiled_gather_equals_the_numpy_gather() -> None:
    rng = np.random.default_rng(8)
    fc = FootprintCells([(float(px), float(py)) for px, py in DEFAULT_POINTS], 0.05)
    costs = rng.choice(np.array([0, 0, 0, 5, 128, 252, 253, LETHAL, NO_INFORMATION], np.uint8),
                       size=(70, 110))
    costs[15:55, 20:90] = rng.integers(0, 60, (40, 70))  # a room without LETHAL
    origin = (0.5, -1.5)
    for shape in ((1,), (9,), (25, 4)):
        x = origin[0] + rng.uniform(-0.6, 110 * 0.05 + 0.6, shape)
        y = origin[1] + rng.uniform(-0.6, 70 * 0.05 + 0.6, shape)
        yaw = rng.uniform(-8.0, 8.0, shape)
        got = fc.max_cost(costs, origin, x, y, yaw)
        want = numpy_gather(fc, costs, origin, x, y, yaw)
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_array_equal(got, want)
    inside = fc.max_cost(costs, origin, origin[0] + 2.7, origin[1] + 1.75, 0.3)
    assert inside.shape == (1,) and 0 < int(inside[0]) < 60
    assert int(fc.max_cost(costs, origin, origin[0] - 5.0, origin[1], 0.0)[0]) == LETHAL
