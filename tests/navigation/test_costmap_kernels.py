"""The local costmap's rebuild with the compiled combine_max and inflate: bit for bit the numpy
updateWithMax and inflation that came before them, on random uint8 grids with every kind of
cell (free, costs, INSCRIBED, LETHAL, NO_INFORMATION), both inflate_unknown settings."""

from __future__ import annotations

import numpy as np

from lowerbase.navigation import kernels
from lowerbase.navigation.kernels import squared_distances
from lowerbase.navigation.layers import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    InflationLayer,
    InflationParams,
    combine_max,
)

VALUES = np.array([0, 0, 0, 0, 1, 50, 128, 252, INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE,
                   NO_INFORMATION], np.uint8)


def combine_numpy(master: np.ndarray, layer: np.ndarray) -> None:
    known = layer != NO_INFORMATION
    take = known & ((master == NO_INFORMATION) | (master < layer))
    master[take] = layer[take]


def inflate_numpy(layer: InflationLayer, master: np.ndarray, resolution: float,
                  inscribed_radius: float) -> None:
    """InflationLayer.apply before the kernel."""
    lethal = master == LETHAL_OBSTACLE
    if not lethal.any():
        return
    table = layer.table(resolution, inscribed_radius)
    d2 = np.empty(master.shape, np.int64)
    squared_distances(lethal, table.size - 1, d2)
    infl = table[d2]
    unknown = master == NO_INFORMATION
    floor = 1 if layer.params.inflate_unknown else INSCRIBED_INFLATED_OBSTACLE
    np.maximum(master, infl, out=master, where=~unknown)
    take = unknown & (infl >= floor)
    master[take] = infl[take]


def grids(rng: np.random.Generator) -> list[np.ndarray]:
    out = []
    for shape in ((1, 1), (3, 17), (100, 100), (40, 61)):
        for p_lethal in (0.0, 0.002, 0.05):
            p = np.full(VALUES.size, 1.0)
            p[VALUES == LETHAL_OBSTACLE] = 0.0
            p /= p.sum()
            g = rng.choice(VALUES, size=shape, p=p)
            g[rng.random(shape) < p_lethal] = LETHAL_OBSTACLE
            out.append(g)
    return out


def test_combine_max_is_the_numpy_update_with_max() -> None:
    rng = np.random.default_rng(3)
    for master in grids(rng):
        layer = rng.choice(VALUES, size=master.shape)
        want = master.copy()
        combine_numpy(want, layer)
        got = master.copy()
        combine_max(got, layer)
        np.testing.assert_array_equal(got, want)
        raw = master.copy()
        kernels.combine_max(raw, layer, NO_INFORMATION)
        np.testing.assert_array_equal(raw, want)


def test_inflation_apply_is_the_numpy_inflation() -> None:
    rng = np.random.default_rng(4)
    for inflate_unknown in (False, True):
        for radius, scaling in ((0.55, 10.0), (0.2, 3.0), (0.0, 10.0)):
            layer = InflationLayer(InflationParams(radius, scaling, inflate_unknown))
            for master in grids(rng):
                for resolution, inscribed in ((0.05, 0.3), (0.1, 0.05)):
                    want = master.copy()
                    inflate_numpy(layer, want, resolution, inscribed)
                    got = master.copy()
                    layer.apply(got, resolution, inscribed)
                    np.testing.assert_array_equal(got, want)
