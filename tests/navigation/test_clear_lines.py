"""The obstacle layer clears its rays with the compiled clear_lines: bit for bit the cells the
numpy line_cells listed (ends made distinct, off-grid cells skipped), on random grids, sensor
cells on and off the window's edge, ends in every direction."""

from __future__ import annotations

import numpy as np

from lowerbase.navigation.kernels import clear_lines
from lowerbase.navigation.layers import line_cells


def clear_numpy(data: np.ndarray, c0: int, r0: int, ec: np.ndarray, er: np.ndarray) -> None:
    """The clearing of ObstacleLayer.update before the kernel."""
    h, w = data.shape
    ends = np.unique(np.clip(er, 0, h - 1) * w + np.clip(ec, 0, w - 1))
    cols, rows = line_cells(c0, r0, ends % w, ends // w)
    ok = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
    data[rows[ok], cols[ok]] = 0


def test_clear_lines_frees_exactly_the_cells_of_line_cells() -> None:
    rng = np.random.default_rng(21)
    for h, w in ((1, 1), (7, 40), (60, 60), (81, 33)):
        for c0, r0 in ((0, 0), (w // 2, h // 2), (w - 1, h - 1), (w // 3, h - 1)):
            for n in (1, 5, 720):
                data = rng.choice(np.array([0, 100, 254, 255], np.uint8), size=(h, w))
                ec = rng.integers(-20, w + 20, n)
                er = rng.integers(-20, h + 20, n)
                want = data.copy()
                clear_numpy(want, c0, r0, ec, er)
                got = data.copy()
                clear_lines(got, c0, r0, np.clip(ec, 0, w - 1), np.clip(er, 0, h - 1), 0)
                np.testing.assert_array_equal(got, want)


def test_runs_of_one_end_cell_clear_what_each_line_does() -> None:
    """Neighbouring rays ending in one cell (a scan's beams far out): the repeats are skipped,
    the cells freed are still those of every line."""
    rng = np.random.default_rng(4)
    for _ in range(20):
        data = rng.choice(np.array([0, 100, 254, 255], np.uint8), size=(60, 60))
        runs = rng.integers(1, 5, 40)
        ec = np.repeat(rng.integers(0, 60, 40), runs)
        er = np.repeat(rng.integers(0, 60, 40), runs)
        assert ((ec[1:] == ec[:-1]) & (er[1:] == er[:-1])).any()
        want = data.copy()
        clear_numpy(want, 30, 31, ec, er)
        got = data.copy()
        clear_lines(got, 30, 31, ec, er, 0)
        np.testing.assert_array_equal(got, want)


def test_ray_end_cells_are_clip_rays_cells() -> None:
    """The compiled end cells: clip_rays (max length, the window's box), world_to_map and the
    clamp onto the grid, as ObstacleLayer.update computed them in numpy; ends near, on and far
    beyond the box, along the axes (dx or dy 0) and at the origin itself."""
    from lowerbase.navigation.kernels import ray_end_cells
    from lowerbase.navigation.layers import Costmap2D, clip_rays

    rng = np.random.default_rng(4)
    cm = Costmap2D(100, 80, 0.05, (-2.5, -1.95), 0)
    box = (cm.origin[0], cm.origin[1], cm.origin[0] + cm.width * cm.resolution - 1e-9,
           cm.origin[1] + cm.height * cm.resolution - 1e-9)
    for ox, oy in ((0.0, 0.0), (-2.49, 1.99), (1.3, -0.7)):
        px = np.concatenate((ox + rng.uniform(-9.0, 9.0, 600), [ox, ox, ox + 1.0, ox - 0.2]))
        py = np.concatenate((oy + rng.uniform(-9.0, 9.0, 600), [oy, oy + 2.0, oy, oy]))
        for max_len in (3.0, 0.5, 40.0):
            ex, ey = clip_rays(ox, oy, px, py, max_len, box)
            wc, wr = cm.world_to_map(ex, ey)
            cols, rows = np.empty(px.size, np.int64), np.empty(px.size, np.int64)
            ray_end_cells(ox, oy, px, py, max_len, *box, cm.origin[0], cm.origin[1],
                          cm.resolution, cm.width, cm.height, cols, rows)
            np.testing.assert_array_equal(cols, np.clip(wc, 0, cm.width - 1))
            np.testing.assert_array_equal(rows, np.clip(wr, 0, cm.height - 1))
