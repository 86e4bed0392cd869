"""The compiled (numba) scan of KLD-sampling's count (:func:`particles.kld_count`).

Particles are taken in order; each one whose histogram bin is new raises the bin count k; the
count stops at the first n (1-based) with ``n > limit[k]`` and ``n >= min_particles``, where
``limit`` is amcl's ``pf_resample_limit`` tabulated by numpy (:func:`particles.kld_limit`).
The bins are floors of the same IEEE quotients numpy took, the rest integer work, and only the
particles the count reaches are binned: what the numpy version (every particle's first
occurrence by ``np.unique``, a cumulative sum, the limit of every k) computed
(tests/world/test_localization.py::test_kld_count_is_the_numpy_count pins it).
"""

from __future__ import annotations

import numpy as np

from lowerbase.jit import compiled

_jit = compiled()


@_jit
def kld_count_poses(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, order: np.ndarray,
                    bin_xy: float, bin_yaw: float, na: int, pi: float, limit: np.ndarray,
                    min_particles: int) -> int:
    """How many of the poses, taken in ``order``, KLD-sampling keeps; their bin keys computed as
    ``particles._bin_index`` computes them (floor of x / bin, y / bin, (yaw + pi) / bin_yaw
    mod na; x and y from their minima over all poses; the key ``(ix * (iy_max + 1) + iy) * 64
    + ia``), only for the particles the scan reaches."""
    n = x.size
    ix_min = iy_min = iy_max = 0
    for i in range(n):
        ix = np.int64(np.floor(x[i] / bin_xy))
        iy = np.int64(np.floor(y[i] / bin_xy))
        if i == 0 or ix < ix_min:
            ix_min = ix
        if i == 0 or iy < iy_min:
            iy_min = iy
        if i == 0 or iy > iy_max:
            iy_max = iy
    span = iy_max - iy_min + 1
    seen = set()
    seen.add(np.int64(0))
    seen.discard(np.int64(0))
    k = 0
    for i in range(order.size):
        j = order[i]
        ix = np.int64(np.floor(x[j] / bin_xy)) - ix_min
        iy = np.int64(np.floor(y[j] / bin_xy)) - iy_min
        ia = np.int64(np.floor((yaw[j] + pi) / bin_yaw)) % na
        key = (ix * span + iy) * 64 + ia
        if key not in seen:
            seen.add(key)
            k += 1
        m = i + 1
        if m > limit[k] and m >= min_particles:
            return m
    return order.size
