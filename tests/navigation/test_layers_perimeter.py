"""``layers._polygon_perimeter`` against skimage's ``draw.polygon_perimeter`` it replaces in
``Costmap2D.polygon_cells``: the same set of cells for footprints at random poses."""

from __future__ import annotations

import numpy as np
from skimage import draw

from lowerbase.navigation.layers import Costmap2D, _polygon_perimeter, footprint_at
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, Footprint


def _cells(r: np.ndarray, c: np.ndarray) -> set[tuple[int, int]]:
    return set(zip(np.asarray(r).tolist(), np.asarray(c).tolist(), strict=True))


def test_the_perimeter_cells_are_skimages() -> None:
    rng = np.random.default_rng(5)
    cm = Costmap2D(100, 100, 0.05, (0.0, 0.0))
    shapes = [DEFAULT_FOOTPRINT, Footprint(((0.3, 0.0), (-0.2, 0.25), (-0.2, -0.25))),
              Footprint(((0.5, 0.4), (-0.5, 0.4), (-0.5, -0.4), (0.5, -0.4)))]
    for k in range(600):
        fp = shapes[k % len(shapes)]
        pose = (float(rng.uniform(-1.0, 6.0)), float(rng.uniform(-1.0, 6.0)),
                float(rng.uniform(-np.pi, np.pi)))
        xy = footprint_at(fp, pose)
        fr = np.round((xy[:, 1] - cm.origin[1]) / cm.resolution - 0.5).astype(int)
        fc = np.round((xy[:, 0] - cm.origin[0]) / cm.resolution - 0.5).astype(int)
        assert _cells(*_polygon_perimeter(fr, fc)) == _cells(*draw.polygon_perimeter(fr, fc))
