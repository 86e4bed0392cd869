"""Compiled (numba) loops of the navigation stack, run every control period or every costmap
update, where a dozen numpy calls on small arrays cost more than the work itself. Each does
exactly what the numpy code it replaced did (integer work, or the same IEEE operations in the
same order; numba without fastmath neither reorders nor fuses them).

:func:`footprint_max`, behind :meth:`FootprintCells.max_cost` on a ``uint8`` costmap: for
each pose (its cell row, column and heading bin, computed by the caller with numpy) the highest
cost under the footprint's cells of that bin; ``NO_INFORMATION`` counts 0, and a pose with any
cell off the map is ``LETHAL`` (tests/navigation/test_footprint_kernel.py pins it against the
numpy gather). The controller checks its arc with it every control period.

:func:`clear_lines`, the obstacle layer's clearing (:meth:`ObstacleLayer.update`): every cell of
the lines from the sensor's cell to each ray's end cell set free, the cells
:func:`lowerbase.navigation.layers.line_cells` lists (tests/navigation/test_clear_lines.py).

Compiled on first use and cached by :func:`lowerbase.jit.compiled`, as the ray caster is.
"""

from __future__ import annotations

import numpy as np

from lowerbase.jit import compiled

_jit = compiled()


@_jit
def footprint_max(costs: np.ndarray, rows: np.ndarray, cols: np.ndarray, bins: np.ndarray,
                  dr: np.ndarray, dc: np.ndarray, lethal: int, no_information: int,
                  out: np.ndarray) -> None:
    """``out[i]``: the highest cost under the footprint at pose i (see the module docstring);
    ``costs`` 2D uint8, ``dr`` / ``dc`` (bins, cells) int64 offsets, the rest 1D int64."""
    h, w = costs.shape
    cells = dr.shape[1]
    for i in range(rows.size):
        r0, c0, k = rows[i], cols[i], bins[i]
        best = 0
        for j in range(cells):
            r = r0 + dr[k, j]
            c = c0 + dc[k, j]
            if r < 0 or c < 0 or r >= h or c >= w:
                best = lethal
                break
            v = int(costs[r, c])
            if v != no_information and v > best:
                best = v
        out[i] = best


@_jit
def clear_lines(data: np.ndarray, c0: int, r0: int, c1: np.ndarray, r1: np.ndarray,
                free: int) -> None:
    """Set ``free`` on every in-grid cell of the lines from (c0, r0) to each (c1, r1), end cells
    included: step k of n (the major axis' length) is the cell
    ``(c0 + floor(k / max(n, 1) * dc + 0.5), r0 + floor(k / max(n, 1) * dr + 0.5))``."""
    h, w = data.shape
    for i in range(c1.size):
        dc = c1[i] - c0
        dr = r1[i] - r0
        n = max(abs(dc), abs(dr))
        m = max(n, 1)
        for k in range(n + 1):
            frac = k / m
            c = c0 + np.int64(np.floor(frac * dc + 0.5))
            r = r0 + np.int64(np.floor(frac * dr + 0.5))
            if 0 <= c < w and 0 <= r < h:
                data[r, c] = free


@_jit
def squared_distances(lethal: np.ndarray, cap: int, out: np.ndarray) -> None:
    """``out``: each cell's squared distance [cells^2] to the nearest ``lethal`` cell, at most
    ``cap`` (what the inflation layer's table reads; its EDT gave the same integers:
    ``rint(edt^2)``). Exact in integers: a column pass (rows to the nearest lethal cell in the
    column), then per row the lower envelope of the parabolas (Felzenszwalb-Huttenlocher) of the
    columns nearer than ``cap``; their crossings are ratios of small integers, so no rounding
    moves a crossing across a cell (tests/navigation/test_inflation_kernel.py)."""
    h, w = lethal.shape
    far = h + w + 1
    g = np.empty((h, w), np.int64)
    for c in range(w):
        d = far
        for r in range(h):
            d = 0 if lethal[r, c] else min(d + 1, far)
            g[r, c] = d
        d = far
        for r in range(h - 1, -1, -1):
            d = 0 if lethal[r, c] else min(d + 1, far)
            if d < g[r, c]:
                g[r, c] = d
    v = np.empty(w, np.int64)
    z = np.empty(w + 1, np.float64)
    for r in range(h):
        k = -1
        for q in range(w):
            gq = g[r, q]
            if gq * gq >= cap:
                continue  # any distance through this column is >= cap
            fq = gq * gq + q * q
            if k < 0:
                k = 0
                v[0] = q
                z[0] = -np.inf
                z[1] = np.inf
                continue
            while True:
                p = v[k]
                s = (fq - (g[r, p] * g[r, p] + p * p)) / (2 * q - 2 * p)
                if s <= z[k] and k > 0:
                    k -= 1
                else:
                    break
            k += 1
            v[k] = q
            z[k] = s
            z[k + 1] = np.inf
        if k < 0:
            for q in range(w):
                out[r, q] = cap
            continue
        j = 0
        for q in range(w):
            while z[j + 1] < q:
                j += 1
            p = v[j]
            d2 = (q - p) * (q - p) + g[r, p] * g[r, p]
            out[r, q] = d2 if d2 < cap else cap
