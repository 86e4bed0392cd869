"""The inflation layer's squared distances come from the compiled exact transform
(kernels.squared_distances); the scipy Euclidean distance transform it replaced is kept here as
the reference: the same inflated costs on random masks (sparse, dense, none, all lethal, single
rows and columns, unknown cells), both inflate_unknown settings and several radii."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from lowerbase.navigation.kernels import squared_distances
from lowerbase.navigation.layers import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    InflationLayer,
    InflationParams,
)


def apply_with_edt(layer: InflationLayer, master: np.ndarray, resolution: float,
                   inscribed_radius: float) -> None:
    """InflationLayer.apply as it was (scipy's EDT, squared and rounded)."""
    lethal = master == LETHAL_OBSTACLE
    if not lethal.any():
        return
    table = layer.table(resolution, inscribed_radius)
    dist = distance_transform_edt(~lethal)
    d2 = np.minimum(np.rint(dist * dist), table.size - 1).astype(np.intp)
    infl = table[d2]
    unknown = master == NO_INFORMATION
    floor = 1 if layer.params.inflate_unknown else INSCRIBED_INFLATED_OBSTACLE
    np.maximum(master, infl, out=master, where=~unknown)
    take = unknown & (infl >= floor)
    master[take] = infl[take]


@pytest.mark.parametrize("radius", [0.0, 0.05, 0.55, 2.0])
@pytest.mark.parametrize("inflate_unknown", [False, True])
def test_inflation_equals_the_edt_inflation(radius: float, inflate_unknown: bool) -> None:
    rng = np.random.default_rng(17)
    layer = InflationLayer(InflationParams(inflation_radius=radius,
                                           inflate_unknown=inflate_unknown))
    for shape in ((1, 1), (1, 40), (37, 1), (100, 100), (64, 151)):
        for density in (0.0, 0.002, 0.02, 0.3, 1.0):
            master = rng.choice(np.array([0, 0, 0, 40, NO_INFORMATION], np.uint8), size=shape)
            master[rng.random(shape) < density] = LETHAL_OBSTACLE
            want = master.copy()
            apply_with_edt(layer, want, 0.05, 0.3)
            got = master.copy()
            layer.apply(got, 0.05, 0.3)
            np.testing.assert_array_equal(got, want)


def test_squared_distances_are_the_rounded_squared_edt() -> None:
    rng = np.random.default_rng(4)
    for shape in ((50, 70), (9, 200), (200, 9)):
        for density in (0.001, 0.01, 0.1):
            lethal = rng.random(shape) < density
            lethal[rng.integers(shape[0]), :] |= rng.random(shape[1]) < 0.5  # a wall row
            if not lethal.any():
                continue
            edt = distance_transform_edt(~lethal)
            for cap in (1, 2, 122, 10**6):
                got = np.empty(shape, np.int64)
                squared_distances(lethal, cap, got)
                want = np.minimum(np.rint(edt * edt), cap).astype(np.int64)
                np.testing.assert_array_equal(got, want)
