"""The compiled (numba) gather of :meth:`LikelihoodField.score`: every particle's beam ends on
the map, their cells and each end's ``z_hit`` term, in one pass over (particles x beams).

It computes what the numpy expressions did, element by element with the same IEEE operations
in the same order (numba without fastmath neither reorders nor fuses them): the end
``px + c bx - s by``, ``py + s bx + c by`` (the particle's cos and sin come from numpy), the
cell ``floor((x - ox) / res)``, inside the grid or not, the flat index (0 outside) and the
float32 ``hit`` (the map's, or ``hit_outside`` as float32 off the map), then
``pz = float64(hit) + z_rand / range_max``. The logarithms and the sums over beams stay numpy's
(tests/world/test_likelihood_kernel.py pins the kernel against the numpy expressions).
"""

from __future__ import annotations

import numpy as np

from lowerbase.jit import compiled

_jit = compiled()


@_jit
def gather(px: np.ndarray, py: np.ndarray, c: np.ndarray, s: np.ndarray, bx: np.ndarray,
           by: np.ndarray, ox: float, oy: float, res: float, width: int, height: int,
           hit_map: np.ndarray, hit_outside: np.float32, z_rand: float, flat: np.ndarray,
           inside: np.ndarray, hit: np.ndarray, pz: np.ndarray) -> None:
    """Fill ``flat`` (int64), ``inside`` (bool), ``hit`` (float32) and ``pz`` (float64), each
    (particles, beams), for particles (px, py, c, s) and beam ends (bx, by) in the base frame."""
    for i in range(px.size):
        x0, y0, ci, si = px[i], py[i], c[i], s[i]
        for j in range(bx.size):
            x = x0 + ci * bx[j] - si * by[j]
            y = y0 + si * bx[j] + ci * by[j]
            col = np.int64(np.floor((x - ox) / res))
            row = np.int64(np.floor((y - oy) / res))
            ok = col >= 0 and col < width and row >= 0 and row < height
            inside[i, j] = ok
            if ok:
                k = row * width + col
                flat[i, j] = k
                h = hit_map[k]
            else:
                flat[i, j] = 0
                h = hit_outside
            hit[i, j] = h
            pz[i, j] = np.float64(h) + z_rand
