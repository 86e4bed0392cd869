"""FootprintCells.max_cost gathers every pose's cells in one array operation; the per-heading
loop it replaced is kept here as the reference: equal on random poses (on, near and off the
map, every heading) over costs with free, inflated, LETHAL and NO_INFORMATION cells."""

from __future__ import annotations

import numpy as np

from lowerbase.navigation.planner import LETHAL, NO_INFORMATION, FootprintCells
from lowerbase.world.footprint import DEFAULT_POINTS
from tests.navigation.footprint_reference import reference_max_cost


def test_batched_max_cost_equals_the_per_heading_loop() -> None:
    rng = np.random.default_rng(3)
    points = [(float(px), float(py)) for px, py in DEFAULT_POINTS]
    fc = FootprintCells(points, 0.05)
    costs = rng.choice(np.array([0, 0, 0, 0, 10, 120, 252, 253, LETHAL, NO_INFORMATION],
                                np.uint8), size=(90, 130))
    costs[20:60, 30:90] = 0  # a free room: maxima below LETHAL too
    costs[35:45, 50:70] = rng.integers(0, 100, (10, 20))
    origin = (-1.0, 2.0)
    for n in (1, 7, 400):
        x = origin[0] + rng.uniform(-0.5, 130 * 0.05 + 0.5, n)
        y = origin[1] + rng.uniform(-0.5, 90 * 0.05 + 0.5, n)
        yaw = rng.uniform(-10.0, 10.0, n)
        got = fc.max_cost(costs, origin, x, y, yaw)
        want = reference_max_cost(fc, costs, origin, x, y, yaw)
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_array_equal(got, want)
    # in the free room: exact small costs, not just LETHAL everywhere
    x = origin[0] + rng.uniform(2.6, 4.4, 300)
    y = origin[1] + rng.uniform(1.2, 2.8, 300)
    yaw = rng.uniform(-np.pi, np.pi, 300)
    got = fc.max_cost(costs, origin, x, y, yaw)
    np.testing.assert_array_equal(got, reference_max_cost(fc, costs, origin, x, y, yaw))
    assert (got < 100).any()
    # scalars broadcast as before
    assert fc.max_cost(costs, origin, 2.0, 4.0, 0.3).shape == (1,)
