"""FootprintCells.max_cost on uint8 costs runs the compiled gather (navigation.kernels): equal
to the per-heading loop of tests/navigation/footprint_reference.py on random poses on, near and
off the map, every heading, 1D and 2D pose arrays, over costs with every cost class."""

from __future__ import annotations

import numpy as np

from lowerbase.navigation.planner import LETHAL, NO_INFORMATION, FootprintCells
from lowerbase.world.footprint import DEFAULT_POINTS
from tests.navigation.footprint_reference import reference_max_cost


def test_compiled_gather_equals_the_per_heading_loop() -> None:
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
        want = reference_max_cost(fc, costs, origin, x, y, yaw)
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_array_equal(got, want)
    inside = fc.max_cost(costs, origin, origin[0] + 2.7, origin[1] + 1.75, 0.3)
    assert inside.shape == (1,) and 0 < int(inside[0]) < 60
    assert int(fc.max_cost(costs, origin, origin[0] - 5.0, origin[1], 0.0)[0]) == LETHAL


def test_headings_on_bin_edges_and_multiples_of_two_pi_fall_in_the_reference_bins() -> None:
    """The 1D fast path (cell and bin computed in the kernel) against the reference at headings
    where the modulo and the rounding are tight: half-bin ties, +-0, +-2 pi multiples, a hair
    below 0 and 2 pi."""
    fc = FootprintCells([(float(px), float(py)) for px, py in DEFAULT_POINTS], 0.05)
    rng = np.random.default_rng(3)
    costs = rng.choice(np.array([0, 40, 200, 253, LETHAL, NO_INFORMATION], np.uint8),
                       size=(60, 60))
    origin = (-1.0, -1.5)
    step = 2.0 * np.pi / fc.bins
    yaw = np.concatenate((np.arange(-3 * fc.bins, 3 * fc.bins) * (0.5 * step),
                          [0.0, -0.0, 1e-300, -1e-300, -1e-17, 2.0 * np.pi, -2.0 * np.pi,
                           2.0 * np.pi - 1e-16, 40.0 * np.pi, -7.0 * np.pi]))
    x = np.full(yaw.shape, origin[0] + 1.52) + rng.uniform(-0.3, 0.3, yaw.shape)
    y = np.full(yaw.shape, origin[1] + 1.47) + rng.uniform(-0.3, 0.3, yaw.shape)
    np.testing.assert_array_equal(fc.max_cost(costs, origin, x, y, yaw),
                                  reference_max_cost(fc, costs, origin, x, y, yaw))
