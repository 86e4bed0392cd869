"""The compiled (numba) noise and merge of one /scan: :func:`measure` and :func:`merge_bins`,
behind :meth:`LidarRig.scan <lowerbase.world.lidar.LidarRig.scan>`.

Both compute, element by element, the numpy expressions of :meth:`Lidar.measure` and
:meth:`ScanMerger.merge` with the same IEEE operations in the same order (numba without
fastmath neither reorders nor fuses them; ``hypot`` is the C library's, as numpy's). The one
transcendental function numpy may compute its own way, ``arctan2`` (a vectorised library on
some CPUs), stays numpy's: the merge is split around it (:func:`merge_points`, numpy's
arctan2, :func:`merge_bins`). tests/world/test_scan_kernel.py pins the rig's scan against the
numpy path, and tests/world/test_lidar_batched.py against the per-lidar reference.
"""

from __future__ import annotations

import numpy as np

from lowerbase.jit import compiled

_jit = compiled()


@_jit
def measure(true: np.ndarray, normal: np.ndarray, uniform: np.ndarray, use_uniform: bool,
            sigma0: float, sigma_per_m: float, range_min: float, range_max: float,
            dropout: float, out: np.ndarray) -> None:
    """:meth:`Lidar.measure`: REP-117 float32 ranges from true distances and the scan's draws."""
    for i in range(true.size):
        t = true[i]
        finite = np.isfinite(t)
        sigma = sigma0 + sigma_per_m * (t if finite else 0.0)
        noisy = t + sigma * normal[i]
        v = min(max(noisy, range_min), range_max) if finite else np.inf
        if t < range_min:
            v = -np.inf
        if use_uniform and uniform[i] < dropout:
            v = np.nan
        out[i] = np.float32(v)


@_jit
def merge_points(r32: np.ndarray, lx: np.ndarray, ly: np.ndarray, cos: np.ndarray,
                 sin: np.ndarray, far: np.ndarray, near: np.ndarray, px: np.ndarray,
                 py: np.ndarray) -> None:
    """Each return's point in base_link (a non-finite return at its beam's reach: +inf at
    range_max, -inf at range_min, NaN anywhere: it is not binned)."""
    for i in range(r32.size):
        r = np.float64(r32[i])
        if not np.isfinite(r):
            r = far[i] if r == np.inf else near[i]
        px[i] = lx[i] + r * cos[i]
        py[i] = ly[i] + r * sin[i]


@_jit
def merge_bins(r32: np.ndarray, px: np.ndarray, py: np.ndarray, rel: np.ndarray, n: int,
               inc: float, full_circle: bool, two_pi: float, out: np.ndarray) -> None:
    """Nearest valid return per bin (``rel``: each point's bearing from ``angle_min``, numpy's
    arctan2); a bin without one is -inf (too close), +inf (looked through) or NaN."""
    best = np.full(n, np.inf)
    too_close = np.zeros(n, dtype=np.bool_)
    clear = np.zeros(n, dtype=np.bool_)
    for i in range(r32.size):
        a = rel[i]
        if a < 0.0 or a >= two_pi:
            a = a % two_pi
        k = np.int64(np.rint(a / inc))
        if full_circle:
            k = k % n
        if k < 0 or k >= n:
            continue
        r = r32[i]
        if np.isfinite(r):
            d = np.hypot(px[i], py[i])
            if d < best[k]:
                best[k] = d
        elif r == -np.inf:
            too_close[k] = True
        elif r == np.inf:
            clear[k] = True
    for k in range(n):
        b = best[k]
        if np.isfinite(b):
            out[k] = np.float32(b)
        elif too_close[k]:
            out[k] = np.float32(-np.inf)
        elif clear[k]:
            out[k] = np.float32(np.inf)
        else:
            out[k] = np.float32(np.nan)
