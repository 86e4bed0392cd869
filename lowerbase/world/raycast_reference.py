"""The numpy grid ray caster: the reference the compiled kernel is tested against.

:func:`cast_grid_reference` is what :func:`lowerbase.world.raycast.cast_grid` computed before
the numba kernel (:mod:`lowerbase.world.raycast_kernel`) took over, kept as its oracle
(tests/world/test_raycast_kernel.py): it casts all rays at once, round after round; each round
advances every ray by distance-field skips, then enumerates the crossings of its next window
as arrays (rays x crossings) and looks them up with ``np.take``. Each ray's arithmetic depends
on that ray alone, which is what lets the kernel redo it one ray at a time.
"""

from __future__ import annotations

import numpy as np

from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.raycast import (
    _SKIP_MIN,
    _SKIP_STEPS,
    _WINDOW,
    _WINDOW_MAX,
    FACE_X,
    FACE_Y,
    GridField,
    GridHits,
    prepare_rays,
)


def cast_grid_reference(mask: np.ndarray, grid: OccupancyGrid, x0: np.ndarray | float,
                        y0: np.ndarray | float, angles: np.ndarray,
                        max_range: float | np.ndarray,
                        grid_field: GridField | None = None) -> GridHits:
    """:func:`cast_grid` in numpy, vectorised over the rays (the same arguments, the same
    result bit for bit): rounds of distance-field skips and crossing windows, the rays that
    hit or leave the grid dropping out after each round."""
    rays = prepare_rays(mask, grid, x0, y0, angles, max_range, grid_field)
    fld, shape, n = rays.field, rays.shape, rays.c.size
    gx, gy, c, s, u_max = rays.gx, rays.gy, rays.c, rays.s, rays.u_max
    res = grid.resolution
    h, w = fld.shape
    stride = w + 2

    dist_u = np.full(n, np.inf)
    face = np.zeros(n, dtype=np.int8)
    coord = np.zeros(n)

    col0 = np.clip(np.floor(gx), -1, w).astype(np.intp) + 1
    row0 = np.clip(np.floor(gy), -1, h).astype(np.intp) + 1
    start_hit = fld.occupied.take(row0 * stride + col0)
    dist_u[start_hit] = 0.0
    # Leave the grid's box: nothing can be hit beyond it (slab method on [0, w] x [0, h]).
    u_max = np.minimum(u_max, _exit_distance(gx, gy, c, s, w, h))

    # Rays from off the grid look at crossings off it too: their cells are clamped.
    clamp = bool(((gx < 0) | (gx > w) | (gy < 0) | (gy > h)).any())
    # Per active ray: where it is [cells], and its next window's length.
    active = np.flatnonzero(~start_hit & (u_max > 0))
    pos = np.zeros(active.size)
    window = np.full(active.size, _WINDOW)
    while active.size:
        ax, ay, ac, as_, am = gx[active], gy[active], c[active], s[active], u_max[active]
        pos = _skip(fld, ax, ay, ac, as_, pos, am)
        go = pos < am
        if not go.all():
            active, pos, window = active[go], pos[go], window[go]
            ax, ay, ac, as_, am = ax[go], ay[go], ac[go], as_[go], am[go]
        if not active.size:
            break
        hi = np.minimum(pos + window, am)
        ux, bx = _window_hits(fld.occupied, w, h, ax, ay, ac, as_, pos, hi, clamp=clamp)
        uy, by = _window_hits(fld.occupied, h, w, ay, ax, as_, ac, pos, hi, transpose=True,
                              clamp=clamp)
        hit_x = ux <= uy
        u = np.where(hit_x, ux, uy)
        got = np.isfinite(u)
        idx = active[got]
        dist_u[idx] = u[got]
        face[idx] = np.where(hit_x[got], FACE_X, FACE_Y)
        coord[idx] = np.where(hit_x[got], grid.origin[0] + bx[got] * res,
                              grid.origin[1] + by[got] * res)
        go = ~got & (hi < am)
        active, pos = active[go], hi[go]
        window = np.minimum(window[go] * 2.0, _WINDOW_MAX)
    return GridHits((dist_u * res).reshape(shape), face.reshape(shape), coord.reshape(shape))


def _skip(field: GridField, gx: np.ndarray, gy: np.ndarray, c: np.ndarray, s: np.ndarray,
          pos: np.ndarray, u_max: np.ndarray) -> np.ndarray:
    """Advance each ray by its clearance while that is at least ``_SKIP_MIN`` (no crossing into
    an occupied cell is passed: see :class:`GridField`), at most ``_SKIP_STEPS`` times; returns
    the new positions [cells]."""
    h, w = field.shape
    stride = float(w + 2)
    pos = pos.copy()
    todo = np.arange(pos.size)
    x, y, cc, ss, p, um = gx + 1.0, gy + 1.0, c, s, pos, u_max  # padded cell coordinates
    # Off the grid (an origin outside it), points are clamped onto the ring of clearance 0.
    clamp = bool(((x < 0) | (x > w + 1) | (y < 0) | (y > h + 1)).any())
    for _ in range(_SKIP_STEPS):
        fx, fy = np.floor(x + p * cc), np.floor(y + p * ss)
        if clamp:
            np.clip(fx, 0, w + 1, out=fx)
            np.clip(fy, 0, h + 1, out=fy)
        r = field.clearance.take((fy * stride + fx).astype(np.intp))
        big = r >= _SKIP_MIN
        p = p + r
        moved = big & (p < um)
        if not moved.all():
            pos[todo] = np.where(big, p, p - r)
            todo = todo[moved]
            if not todo.size:
                return pos
            x, y, cc, ss, p, um = x[moved], y[moved], cc[moved], ss[moved], p[moved], um[moved]
    pos[todo] = p
    return pos


def _exit_distance(gx: np.ndarray, gy: np.ndarray, c: np.ndarray, s: np.ndarray, w: int,
                   h: int) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 0, (w - gx) / c, np.where(c < 0, -gx / c, np.inf))
        ty = np.where(s > 0, (h - gy) / s, np.where(s < 0, -gy / s, np.inf))
    return np.maximum(np.minimum(tx, ty), 0.0)


def _window_hits(occupied: np.ndarray, n_along: int, n_across: int, ga: np.ndarray,
                 gb: np.ndarray, ca: np.ndarray, cb: np.ndarray, u_lo: np.ndarray,
                 u_hi: np.ndarray, transpose: bool = False, clamp: bool = True
                 ) -> tuple[np.ndarray, np.ndarray]:
    """First occupied cell entered through a boundary a = const with u in [u_lo, u_hi).

    ``a`` is the axis whose boundaries are crossed (x, or y with ``transpose``), ``b`` the other;
    ``occupied`` is the padded flat mask of :class:`GridField`. Returns the ray distance [cells]
    (inf: none) and the boundary's a-coordinate [cells]. The k-th boundary's distance is
    ``(d0 + k) / |ca|`` whatever the window: windows only choose which k are looked at.
    ``clamp=False`` when every ray starts on the grid (then every crossing looked at lies on
    the grid or its padding ring: no clipping is needed).
    """
    m = ga.size
    abs_ca = np.abs(ca)
    moving = abs_ca > 1e-12
    up = ca > 0
    base = np.where(up, np.floor(ga) + 1.0, np.floor(ga))      # first boundary crossed
    d0 = np.abs(base - ga)                                      # its distance along a [cells]
    with np.errstate(divide="ignore", invalid="ignore"):
        k_lo = np.where(moving, np.ceil(u_lo * abs_ca - d0), 0.0)
        k_hi = np.where(moving, np.ceil(u_hi * abs_ca - d0), 0.0)
    k_lo = np.maximum(k_lo, 0.0)
    count = np.maximum(k_hi - k_lo, 0.0)
    width = int(count.max(initial=0.0))
    if width == 0:
        return np.full(m, np.inf), np.zeros(m)
    den = np.where(moving, abs_ca, 1.0)
    steps = np.arange(width, dtype=float)
    k = k_lo[:, None] + steps
    u = d0[:, None] + k
    u /= den[:, None]
    # The cell entered: a = boundary - (ca < 0) (integers, exact in int arithmetic) and
    # b = floor(gb + u cb). Its flat index in the padded mask (rows of ``stride`` cells; with
    # ``transpose`` a is the row) is (a + 1) a_mul + (b + 1) b_mul.
    stride = (n_across if transpose else n_along) + 2
    a_mul, b_mul = (stride, 1) if transpose else (1, stride)
    sign = np.where(up, 1, -1)
    a0 = (base - (ca < 0)).astype(np.intp) + sign * k_lo.astype(np.intp)  # the cell at k_lo
    v = u * cb[:, None]
    v += gb[:, None]
    cell_b = np.floor(v, out=v).astype(np.intp)
    if clamp:
        cell_a = a0[:, None] + sign[:, None] * np.arange(width, dtype=np.intp)
        np.clip(cell_a, -1, n_along, out=cell_a)   # off the grid: onto the free padding ring
        np.clip(cell_b, -1, n_across, out=cell_b)
        index = cell_a * a_mul
    else:  # the same integers, with the constants folded into the per-ray start
        index = (sign * a_mul)[:, None] * np.arange(width, dtype=np.intp)
        index += (a0 * a_mul)[:, None]
    if b_mul != 1:
        cell_b *= b_mul
    index += cell_b
    index += a_mul + b_mul
    # Past a ray's own count the index may leave the mask (clipped; never used): the first
    # occupied entry is a hit only within the count.
    occ = occupied.take(index, mode="clip")
    first = np.argmax(occ, axis=1)
    rows = np.arange(m)
    any_hit = occ[rows, first] & (first < count)
    u_hit = np.where(any_hit, u[rows, first], np.inf)
    boundary = base + np.where(up, 1.0, -1.0) * (k_lo + first)
    return u_hit, np.where(any_hit, boundary, 0.0)
