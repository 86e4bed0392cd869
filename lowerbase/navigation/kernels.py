"""Compiled (numba) loops of the navigation stack, run every control period or every costmap
update, where a dozen numpy calls on small arrays cost more than the work itself. Each does
exactly what the numpy code it replaced did (integer work, or the same IEEE operations in the
same order; numba without fastmath neither reorders nor fuses them).

:func:`footprint_max`, behind :meth:`FootprintCells.max_cost` on a ``uint8`` costmap: for
each pose (its cell row, column and heading bin, computed by the caller with numpy) the highest
cost under the footprint's cells of that bin; ``NO_INFORMATION`` counts 0, and a pose with any
cell off the map is ``LETHAL`` (tests/navigation/test_footprint_kernel.py pins it against the
numpy gather). The controller checks its arc with it every control period.

:func:`polygon_cells`, behind :meth:`Costmap2D.polygon_cells` (the footprint cleared from the
local costmap at every update): skimage's ``draw.polygon`` and ``draw.line`` outline, the same
cells in the same order (tests/navigation/test_polygon_cells_kernel.py).

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
    ``(c0 + floor(k / max(n, 1) * dc + 0.5), r0 + floor(k / max(n, 1) * dr + 0.5))``. A line
    to the end cell of the one before it is that line again (neighbouring rays far out end in
    one cell: about half a scan's): skipped, as every cell is set to the one value ``free``."""
    h, w = data.shape
    for i in range(c1.size):
        if i > 0 and c1[i] == c1[i - 1] and r1[i] == r1[i - 1]:
            continue
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


@_jit
def footprint_max_at(costs: np.ndarray, ox: float, oy: float, res: float, x: np.ndarray,
                     y: np.ndarray, yaw: np.ndarray, bins: int, dr: np.ndarray,
                     dc: np.ndarray, lethal: int, no_information: int, out: np.ndarray
                     ) -> None:
    """:func:`footprint_max` at poses (x, y, yaw) [m, rad], each pose's cell and heading bin
    computed as :meth:`FootprintCells.max_cost` computes them with numpy: row and column
    ``floor((y - oy) / res)``, ``floor((x - ox) / res)``; bin ``round(mod(yaw, 2 pi) / (2 pi)
    * bins) % bins`` (Python's float modulo is numpy's, round half to even)."""
    two_pi = 2.0 * np.pi
    n = x.size
    rows = np.empty(n, dtype=np.int64)
    cols = np.empty(n, dtype=np.int64)
    ks = np.empty(n, dtype=np.int64)
    for i in range(n):
        rows[i] = np.int64(np.floor((y[i] - oy) / res))
        cols[i] = np.int64(np.floor((x[i] - ox) / res))
        ks[i] = np.int64(np.rint((yaw[i] % two_pi) / two_pi * bins)) % bins
    footprint_max(costs, rows, cols, ks, dr, dc, lethal, no_information, out)


@_jit
def _in_polygon(xp: np.ndarray, yp: np.ndarray, x: float, y: float) -> bool:
    """skimage's point_in_polygon (O'Rourke's ray crossings) is not 0: inside, on a vertex
    (within 1e-12) or on an edge (left and right crossings of different parity)."""
    eps = 1e-12
    nv = xp.size
    right = left = 0
    x1 = xp[nv - 1] - x
    y1 = yp[nv - 1] - y
    for i in range(nv):
        x0 = xp[i] - x
        y0 = yp[i] - y
        if -eps < x0 < eps and -eps < y0 < eps:
            return True
        if (y0 > 0) != (y1 > 0) and (x0 * y1 - x1 * y0) / (y1 - y0) > 0:
            right += 1
        if (y0 < 0) != (y1 < 0) and (x0 * y1 - x1 * y0) / (y1 - y0) < 0:
            left += 1
        x1 = x0
        y1 = y0
    return (right & 1) != (left & 1) or (right & 1) == 1


@_jit
def polygon_cells(fr: np.ndarray, fc: np.ndarray, ir: np.ndarray, ic: np.ndarray, h: int,
                  w: int) -> tuple[np.ndarray, np.ndarray, bool]:
    """:meth:`Costmap2D.polygon_cells` in one call: skimage's ``draw.polygon(fr, fc)`` (the
    cells whose centre is inside or on the outline, :func:`_in_polygon`; rows and columns
    from max(0, min) to ceil(max)), then ``draw.line`` (Bresenham) along the outline between
    the rounded vertices ``ir`` / ``ic``, the cells off an h x w grid dropped: (cols, rows, any
    dropped), in that order (tests/navigation/test_polygon_cells_kernel.py against skimage)."""
    nv = fr.size
    minr = int(max(0.0, fr.min()))
    maxr = int(np.ceil(fr.max()))
    minc = int(max(0.0, fc.min()))
    maxc = int(np.ceil(fc.max()))
    area = max(maxr - minr + 1, 0) * max(maxc - minc + 1, 0)
    line = 0
    for i in range(nv):
        j = (i + 1) % nv
        line += max(abs(ir[j] - ir[i]), abs(ic[j] - ic[i])) + 1
    rows = np.empty(area + line, dtype=np.int64)
    cols = np.empty(area + line, dtype=np.int64)
    n = 0
    dropped = False
    for r in range(minr, maxr + 1):
        y = float(r)
        for c in range(minc, maxc + 1):
            x = float(c)
            if _in_polygon(fc, fr, x, y):
                if r < h and c < w:
                    rows[n] = r
                    cols[n] = c
                    n += 1
                else:
                    dropped = True
    for i in range(nv):  # skimage's _line, variable for variable
        j = (i + 1) % nv
        r, c, r1, c1 = ir[i], ic[i], ir[j], ic[j]
        dr, dc = abs(r1 - r), abs(c1 - c)
        sc = 1 if c1 - c > 0 else -1
        sr = 1 if r1 - r > 0 else -1
        steep = dr > dc
        if steep:
            r, c, dr, dc, sr, sc = c, r, dc, dr, sc, sr
        d = 2 * dr - dc
        for k in range(dc + 1):
            if k == dc:
                rr, cc = r1, c1
            elif steep:
                rr, cc = c, r
            else:
                rr, cc = r, c
            if 0 <= rr < h and 0 <= cc < w:
                rows[n] = rr
                cols[n] = cc
                n += 1
            else:
                dropped = True
            if k < dc:
                while d >= 0:
                    r += sr
                    d -= 2 * dc
                c += sc
                d += 2 * dr
    return cols[:n], rows[:n], dropped


@_jit
def ray_end_cells(ox: float, oy: float, px: np.ndarray, py: np.ndarray, max_len: float,
                  xmin: float, ymin: float, xmax: float, ymax: float, x0: float, y0: float,
                  res: float, w: int, h: int, cols: np.ndarray, rows: np.ndarray) -> None:
    """The cells where the obstacle layer's clearing rays end, clamped onto the grid: each ray
    from (ox, oy) towards (px, py) shortened to ``max_len`` and to the box, as
    :func:`~lowerbase.navigation.layers.clip_rays` computes it, then the cell
    ``floor((x - x0) / res)`` as ``Costmap2D.world_to_map``, clamped
    (tests/navigation/test_clear_lines.py::test_ray_end_cells_are_clip_rays_cells)."""
    for i in range(px.size):
        dx, dy = px[i] - ox, py[i] - oy
        t = min(1.0, max_len / max(np.hypot(dx, dy), 1e-12))
        tx = (xmax - ox) / dx if dx > 0 else ((xmin - ox) / dx if dx < 0 else np.inf)
        ty = (ymax - oy) / dy if dy > 0 else ((ymin - oy) / dy if dy < 0 else np.inf)
        t = min(t, min(tx, ty))
        c = np.int64(np.floor((ox + t * dx - x0) / res))
        r = np.int64(np.floor((oy + t * dy - y0) / res))
        cols[i] = min(max(c, 0), w - 1)
        rows[i] = min(max(r, 0), h - 1)


@_jit
def mark_points(data: np.ndarray, px: np.ndarray, py: np.ndarray, pz: np.ndarray, ox: float,
                oy: float, oz: float, z_min: float, z_max: float, range_sq: float, x0: float,
                y0: float, res: float, value: int) -> None:
    """The obstacle layer's marking (:meth:`ObstacleLayer.update`): ``value`` on the cell of
    every point within the height limits (``z_min <= z <= z_max``) whose squared distance from
    the origin ``(dx * dx + dy * dy) + dz * dz`` is below ``range_sq`` and whose cell
    ``floor((x - x0) / res)``, ``floor((y - y0) / res)`` is on the grid: the numpy marking's
    expressions in its order (tests/navigation/test_mark_points.py)."""
    h, w = data.shape
    for i in range(px.size):
        z = pz[i]
        dx, dy, dz = px[i] - ox, py[i] - oy, z - oz
        d2 = (dx * dx + dy * dy) + dz * dz
        if not (z >= z_min and z <= z_max and d2 < range_sq):
            continue
        c = np.floor((px[i] - x0) / res)
        r = np.floor((py[i] - y0) / res)
        if 0.0 <= c < w and 0.0 <= r < h:
            data[np.int64(r), np.int64(c)] = value


@_jit
def combine_max(master: np.ndarray, layer: np.ndarray, no_information: int) -> None:
    """costmap_2d's updateWithMax in place (:func:`lowerbase.navigation.layers.combine_max`):
    each known cell of ``layer`` raises ``master``'s, and a ``master`` cell without information
    takes the layer's; both 2D ``uint8`` of one shape (tests/navigation/test_costmap_kernels.py)."""
    h, w = master.shape
    for r in range(h):
        for c in range(w):
            v = layer[r, c]
            if v != no_information:
                m = master[r, c]
                if m == no_information or m < v:
                    master[r, c] = v


@_jit
def inflate(master: np.ndarray, d2: np.ndarray, table: np.ndarray, no_information: int,
            floor: int) -> None:
    """The inflation layer's last step (:meth:`InflationLayer.apply`): each cell's cost from
    ``table`` by its squared distance ``d2`` raises a known ``master`` cell, and replaces an
    unknown one when at least ``floor`` (tests/navigation/test_costmap_kernels.py)."""
    h, w = master.shape
    for r in range(h):
        for c in range(w):
            v = table[d2[r, c]]
            m = master[r, c]
            if m == no_information:
                if v >= floor:
                    master[r, c] = v
            elif v > m:
                master[r, c] = v


@_jit
def scan_points(ranges: np.ndarray, cos: np.ndarray, sin: np.ndarray, inf_is_valid: bool,
                range_min: float, range_max: float, x: float, y: float, c: float, s: float,
                out: np.ndarray) -> int:
    """A LaserScan's returns as map points at the robot's pose (x, y, heading's cosine ``c``
    and sine ``s``) into ``out`` (n, 3) from row 0; how many. As
    :func:`lowerbase.navigation.costmap.scan_observation` did in numpy: +inf is ``range_max -
    1e-4`` when ``inf_is_valid``; returns with range_min <= r < range_max kept; the point in
    base_link ``(r * cos, r * sin, 0)``, then ``(x + c * px - s * py, y + s * px + c * py,
    0)`` (tests/navigation/test_mark_points.py)."""
    k = 0
    for i in range(ranges.size):
        r = np.float64(ranges[i])
        if inf_is_valid and r == np.inf:
            r = range_max - 1e-4
        if not (np.isfinite(r) and r >= range_min and r < range_max):
            continue
        px = r * cos[i]
        py = r * sin[i]
        out[k, 0] = x + c * px - s * py
        out[k, 1] = y + s * px + c * py
        out[k, 2] = 0.0
        k += 1
    return k
