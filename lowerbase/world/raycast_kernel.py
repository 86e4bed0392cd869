"""The compiled (numba) grid ray caster behind :func:`lowerbase.world.raycast.cast_grid`.

One ray at a time, the kernel walks the algorithm of the numpy reference
(:func:`lowerbase.world.raycast_reference.cast_grid_reference`) step by step: the distance-field
skips (at most ``skip_steps`` per round, while the clearance is at least ``skip_min`` cells),
then a window of cell boundary crossings, boundary by boundary, first those x = const then
those y = const, each crossing's distance, cell and face computed by the same IEEE expressions
in the same order (numba without fastmath neither reorders nor fuses them). The numpy reference
computes each ray's rounds independently of the other rays, so the two agree bit for bit
(tests/world/test_raycast_kernel.py). The one liberty taken: the y crossings of a window are
walked only up to the x hit's distance (a later one would lose to it: ``ux <= uy`` picks x).

Compiled on first use and cached as :mod:`lowerbase.jit` says; where no cache location is
writable it is compiled in memory.
"""

from __future__ import annotations

import numpy as np

from lowerbase.jit import compiled

_jit = compiled(error_model="numpy")


@_jit
def _skip(clearance: np.ndarray, w: int, h: int, x: float, y: float, c: float, s: float,
          pos: float, u_max: float, skip_min: float, skip_steps: int) -> float:
    """The ray's position [cells] after its skips of this round (``_skip`` of the reference)."""
    stride = w + 2
    xp, yp = x + 1.0, y + 1.0      # padded cell coordinates
    p = pos
    for _ in range(skip_steps):
        fx = np.floor(xp + p * c)
        fy = np.floor(yp + p * s)
        fx = min(max(fx, 0.0), float(w + 1))   # off the grid: onto the ring of clearance 0
        fy = min(max(fy, 0.0), float(h + 1))
        r = np.float64(clearance[int(fy) * stride + int(fx)])
        big = r >= skip_min
        p = p + r
        if not (big and p < u_max):
            return p if big else p - r
    return p


@_jit
def _axis_hit(occupied: np.ndarray, n_along: int, n_across: int, transpose: bool, ga: float,
              gb: float, ca: float, cb: float, u_lo: float, u_hi: float,
              u_stop: float) -> tuple[float, float]:
    """First occupied cell entered through a boundary a = const with u in [u_lo, u_hi) and
    u < ``u_stop``: (its distance [cells], the boundary's a) or (inf, 0)
    (``_window_hits`` of the reference, one ray)."""
    abs_ca = abs(ca)
    moving = abs_ca > 1e-12
    up = ca > 0
    base = np.floor(ga) + 1.0 if up else np.floor(ga)
    d0 = abs(base - ga)
    k_lo = 0.0
    k_hi = 0.0
    if moving:
        k_lo = np.ceil(u_lo * abs_ca - d0)
        k_hi = np.ceil(u_hi * abs_ca - d0)
    k_lo = max(k_lo, 0.0)
    count = max(k_hi - k_lo, 0.0)
    den = abs_ca if moving else 1.0
    stride = (n_across if transpose else n_along) + 2
    a_mul = stride if transpose else 1
    b_mul = 1 if transpose else stride
    sign = 1 if up else -1
    a0 = int(base - (1.0 if ca < 0 else 0.0)) + sign * int(k_lo)
    step = 1.0 if up else -1.0
    for i in range(int(count)):
        k = k_lo + float(i)
        u = (d0 + k) / den
        if u >= u_stop:
            break
        cell_a = min(max(a0 + sign * i, -1), n_along)   # off the grid: the free padding ring
        cell_b = min(max(int(np.floor(u * cb + gb)), -1), n_across)
        if occupied[(cell_a + 1) * a_mul + (cell_b + 1) * b_mul]:
            return u, base + step * (k_lo + float(i))
    return np.inf, 0.0


@_jit
def cast_rays(occupied: np.ndarray, clearance: np.ndarray, h: int, w: int, gx: np.ndarray,
              gy: np.ndarray, c: np.ndarray, s: np.ndarray, u_max: np.ndarray, ox: float,
              oy: float, res: float, skip_min: float, window0: float, window_max: float,
              skip_steps: int, dist: np.ndarray, face: np.ndarray, coord: np.ndarray) -> None:
    """Cast every ray into ``dist`` [m] (inf: no hit), ``face`` (0 none, 1 x, 2 y) and
    ``coord`` [m]; ``occupied`` and ``clearance`` are a GridField's, the rest as the
    reference's arrays (grid cells, unit directions, ranges [cells])."""
    stride = w + 2
    for i in range(gx.size):
        x, y, cc, ss = gx[i], gy[i], c[i], s[i]
        face[i] = 0
        coord[i] = 0.0
        col0 = int(min(max(np.floor(x), -1.0), float(w))) + 1
        row0 = int(min(max(np.floor(y), -1.0), float(h))) + 1
        if occupied[row0 * stride + col0]:
            dist[i] = 0.0 * res
            continue
        dist[i] = np.inf
        # Leave the grid's box: nothing can be hit beyond it (slab method on [0, w] x [0, h]).
        tx = (w - x) / cc if cc > 0 else (-x / cc if cc < 0 else np.inf)
        ty = (h - y) / ss if ss > 0 else (-y / ss if ss < 0 else np.inf)
        am = min(u_max[i], max(min(tx, ty), 0.0))
        if not am > 0:
            continue
        pos = 0.0
        window = window0
        while True:
            pos = _skip(clearance, w, h, x, y, cc, ss, pos, am, skip_min, skip_steps)
            if not pos < am:
                break
            hi = min(pos + window, am)
            ux, bx = _axis_hit(occupied, w, h, False, x, y, cc, ss, pos, hi, np.inf)
            uy, by = _axis_hit(occupied, h, w, True, y, x, ss, cc, pos, hi, ux)
            if ux <= uy:
                if ux < np.inf:
                    dist[i] = ux * res
                    face[i] = 1
                    coord[i] = ox + bx * res
                    break
            else:
                dist[i] = uy * res
                face[i] = 2
                coord[i] = oy + by * res
                break
            if not hi < am:
                break
            pos = hi
            window = min(window * 2.0, window_max)
