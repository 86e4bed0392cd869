"""Compiled loops of the controller (:class:`~lowerbase.navigation.controller.PathController`),
run every control period, where a dozen numpy calls on small arrays cost more than the work.

:func:`nearest_ahead` and :func:`first_beyond` are its path bookkeeping (``_advance``: the
nearest path point in a window ahead, numpy's ``argmin`` of ``hypot``, the first of equals;
``_carrot``: the first point at least the lookahead away), with numpy's ``hypot`` on the same
differences (numba's is libm's, as numpy's).

The collision check (:meth:`PathController._checked`) in one call, :func:`arc_hits_lethal`:
the footprint along the commanded arc, stopping at the first pose that meets a LETHAL cell. It
does what the numpy code it replaced did, the same IEEE operations in the same order (numba
without fastmath neither reorders nor fuses them; its ``sin``/``cos`` are libm's, as numpy's
float64 ones): :func:`arc_poses`, the arc's ``n`` parameters ``s = k * (1 / n)`` (the last
exactly 1, ``np.linspace(0, 1, n + 1)[1:]``), times ``t = s * duration``, headings ``th = yaw
+ w * t`` and points on the circle (or the line), then each pose's cell and heading bin as
:func:`lowerbase.navigation.kernels.footprint_max_at`. It answers whether any pose's footprint
leaves the map or covers a cell of cost >= ``lethal`` other than ``no_information``: the
``(cost >= LETHAL).any()`` over :meth:`FootprintCells.max_cost` the controller tested, without
the per-pose maxima; a pose in the same cell and bin as the one before is not looked at again.
tests/navigation/test_pursuit_kernels.py pins each against the numpy code it replaced.
"""

from __future__ import annotations

import math

import numpy as np

from lowerbase.jit import compiled

_jit = compiled()


@_jit
def arc_poses(x: float, y: float, yaw: float, v: float, w: float, reach: float, turn: float,
              n: int, out: np.ndarray) -> None:
    """``out`` (n, 3): the arc's poses (x, y, heading) from (x, y, yaw) under (v, w) [m/s,
    rad/s] over ``reach`` m, or ``turn`` rad in place when |v| <= 1e-6 (see the module
    docstring)."""
    inv = 1.0 / n
    direction = 1.0 if v >= 0 else -1.0
    if abs(v) > 1e-6:
        scale = reach / abs(v)
    else:
        scale = turn / max(abs(w), 1e-6)
        direction = 0.0
    vv = direction * abs(v) if direction != 0.0 else 0.0
    circle = abs(w) > 1e-6 and direction != 0.0
    r = vv / w if circle else 0.0
    sin0, cos0 = math.sin(yaw), math.cos(yaw)
    for i in range(1, n + 1):
        s = 1.0 if i == n else i * inv
        t = s * scale
        th = yaw + w * t
        if circle:
            out[i - 1, 0] = x + r * (np.sin(th) - sin0)
            out[i - 1, 1] = y - r * (np.cos(th) - cos0)
        else:
            out[i - 1, 0] = x + vv * t * cos0
            out[i - 1, 1] = y + vv * t * sin0
        out[i - 1, 2] = th


@_jit
def arc_hits_lethal(costs: np.ndarray, ox: float, oy: float, res: float, x: float, y: float,
                    yaw: float, v: float, w: float, reach: float, turn: float, n: int,
                    bins: int, dr: np.ndarray, dc: np.ndarray, lethal: int,
                    no_information: int) -> bool:
    """Whether the footprint (cells ``dr``/``dc`` per heading bin) along :func:`arc_poses`
    meets a lethal cell or leaves ``costs`` (see the module docstring)."""
    poses = np.empty((n, 3))
    arc_poses(x, y, yaw, v, w, reach, turn, n, poses)
    h, wd = costs.shape
    cells = dr.shape[1]
    two_pi = 2.0 * np.pi
    last_r = last_c = last_k = np.int64(-1)
    for i in range(n):
        r0 = np.int64(np.floor((poses[i, 1] - oy) / res))
        c0 = np.int64(np.floor((poses[i, 0] - ox) / res))
        k = np.int64(np.rint((poses[i, 2] % two_pi) / two_pi * bins)) % bins
        if i > 0 and r0 == last_r and c0 == last_c and k == last_k:
            continue
        last_r, last_c, last_k = r0, c0, k
        for j in range(cells):
            rr = r0 + dr[k, j]
            cc = c0 + dc[k, j]
            if rr < 0 or cc < 0 or rr >= h or cc >= wd:
                return True
            value = np.int64(costs[rr, cc])
            if value != no_information and value >= lethal:
                return True
    return False


@_jit
def nearest_ahead(path: np.ndarray, start: int, end: int, x: float, y: float) -> int:
    """The index in ``start:end`` of ``path`` (n, >= 2) nearest to (x, y), the first of equal
    ones: ``start + argmin(hypot(path[start:end, 0] - x, path[start:end, 1] - y))``."""
    best = np.inf
    k = start
    for i in range(start, end):
        d = np.hypot(path[i, 0] - x, path[i, 1] - y)
        if np.isnan(d):
            return i  # argmin's first NaN
        if d < best or i == start:
            best = d
            k = i
    return k


@_jit
def first_beyond(path: np.ndarray, start: int, x: float, y: float, distance: float) -> int:
    """The first index from ``start`` of a ``path`` point at least ``distance`` from (x, y)
    (``hypot(px - x, py - y) >= distance``); the last index when none is."""
    for i in range(start, path.shape[0]):
        if np.hypot(path[i, 0] - x, path[i, 1] - y) >= distance:
            return i
    return path.shape[0] - 1
