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


@_jit
def _root(parent: np.ndarray, a: int) -> int:
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@_jit
def cluster_ids(ix: np.ndarray, iy: np.ndarray, ia: np.ndarray, ny: int, na: int
                ) -> np.ndarray:
    """Cluster id per particle from its histogram bin (ix, iy >= 0, ia in [0, na)): bins
    connected through any of their 26 neighbours, the heading wrapping round (na - 1 touches
    0), as ``particles.cluster_labels_ndimage`` connects them; the ids ordered as its labels
    are (by each cluster's first bin in (ix, iy, ia) order), numbered from 0."""
    n = ix.size
    cell_of = {np.int64(0): np.int64(0)}
    del cell_of[np.int64(0)]  # a typed empty dict of int64 -> int64
    keys = np.empty(n, dtype=np.int64)
    cells = np.empty(n, dtype=np.int64)
    count = 0
    for i in range(n):
        key = (ix[i] * ny + iy[i]) * na + ia[i]
        if key in cell_of:
            cells[i] = cell_of[key]
        else:
            cell_of[key] = count
            keys[count] = key
            cells[i] = count
            count += 1
    parent = np.arange(count)
    for c in range(count):
        key = keys[c]
        a = key % na
        y = (key // na) % ny
        x = key // (na * ny)
        for dx in range(-1, 2):
            xx = x + dx
            if xx < 0:
                continue
            for dy in range(-1, 2):
                yy = y + dy
                if yy < 0 or yy >= ny:
                    continue
                for da in range(-1, 2):
                    near = (xx * ny + yy) * na + (a + da) % na
                    if near in cell_of:
                        ra, rb = _root(parent, c), _root(parent, cell_of[near])
                        if ra != rb:
                            parent[max(ra, rb)] = min(ra, rb)
    first = np.full(count, np.iinfo(np.int64).max)  # each cluster's smallest key
    for c in range(count):
        r = _root(parent, c)
        first[r] = min(first[r], keys[c])
    order = np.argsort(first)  # roots first (the others keep the maximum), by first key
    rank = np.empty(count, dtype=np.int64)
    for k in range(count):
        rank[order[k]] = k
    out = np.empty(n, dtype=np.int64)
    for i in range(n):
        out[i] = rank[_root(parent, cells[i])]
    return out
