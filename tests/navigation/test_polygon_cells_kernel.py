"""The compiled ``polygon_cells`` (kernels.py) against skimage's ``draw.polygon`` and
``draw.line`` that ``Costmap2D.polygon_cells`` used: the same cells in the same order, the cells
off the grid dropped, for footprints at random poses and random polygons on and off the grid."""

from __future__ import annotations

import math

import numpy as np
from skimage import draw

from lowerbase.navigation.kernels import polygon_cells
from lowerbase.navigation.layers import Costmap2D, footprint_at
from lowerbase.world.footprint import DEFAULT_FOOTPRINT


def skimage_cells(fr: np.ndarray, fc: np.ndarray, h: int, w: int
                  ) -> tuple[np.ndarray, np.ndarray, bool]:
    """What polygon_cells computed with skimage: polygon, then the Bresenham outline."""
    rr, cc = draw.polygon(fr, fc)
    ir, ic = np.round(fr).astype(int), np.round(fc).astype(int)
    lines = [draw.line(int(ir[i]), int(ic[i]), int(ir[(i + 1) % len(ir)]),
                       int(ic[(i + 1) % len(ic)])) for i in range(len(ir))]
    rows = np.concatenate([rr] + [lr for lr, _ in lines]).astype(np.int64)
    cols = np.concatenate([cc] + [lc for _, lc in lines]).astype(np.int64)
    ok = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
    return cols[ok], rows[ok], bool(not ok.all())


def check(fr: np.ndarray, fc: np.ndarray, h: int, w: int) -> None:
    ir, ic = np.round(fr).astype(np.int64), np.round(fc).astype(np.int64)
    cols, rows, off = polygon_cells(fr, fc, ir, ic, h, w)
    ecols, erows, eoff = skimage_cells(fr, fc, h, w)
    assert off == eoff
    np.testing.assert_array_equal(rows, erows)
    np.testing.assert_array_equal(cols, ecols)


def test_footprints_at_random_poses_give_skimage_s_cells() -> None:
    cm = Costmap2D(120, 100, 0.05, (-3.0, -2.5), 0)
    rng = np.random.default_rng(5)
    for _ in range(300):
        pose = (rng.uniform(-3.5, 3.5), rng.uniform(-3.0, 3.0), rng.uniform(-math.pi, math.pi))
        xy = footprint_at(DEFAULT_FOOTPRINT, pose)
        fc = (xy[:, 0] - cm.origin[0]) / cm.resolution - 0.5
        fr = (xy[:, 1] - cm.origin[1]) / cm.resolution - 0.5
        check(fr, fc, cm.height, cm.width)


def test_random_polygons_and_degenerate_ones_give_skimage_s_cells() -> None:
    rng = np.random.default_rng(8)
    for _ in range(400):
        n = int(rng.integers(3, 9))
        fr = rng.uniform(-6.0, 26.0, n)
        fc = rng.uniform(-6.0, 26.0, n)
        if rng.random() < 0.2:
            fr = np.round(fr)  # vertices on cell centres, edges through them
        check(fr, fc, 20, 20)
    check(np.array([3.0, 3.0, 3.0]), np.array([2.0, 2.0, 2.0]), 10, 10)  # one point
    check(np.array([-4.0, -2.0, -3.0]), np.array([1.0, 5.0, 3.0]), 10, 10)  # all off the grid
