"""The element-wise end of the IMU's noise block (:meth:`.imu.ImuModel._block`) compiled: what
follows the two matrix products, in one pass instead of a dozen numpy calls.

The same IEEE operations in the same order as the numpy form (no fastmath): each
Gauss-Markov term ``local + decay * before``, summed over the terms in order (numpy's sum over
the first axis adds the rows one after another), the walk's cumulative sum, ``* walk_dt``,
``+ rw``, the fold (``np.mod`` is C's ``fmod`` with numpy's sign fix), ``+`` the two, and the
white noise ``* sigma``; tests/firmware_model/test_imu_block.py checks them bit for bit. Used
where the compiled control loop runs (:func:`finish` is None when numba cannot compile).
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from lowerbase.jit import compiled

log = logging.getLogger(__name__)


@compiled()
def finish_block(local: np.ndarray, decay: np.ndarray, before: np.ndarray, free: np.ndarray,
                 walk_dt: np.ndarray, rw: np.ndarray, b: np.ndarray, b4: np.ndarray,
                 b2: np.ndarray, white: np.ndarray, sigma: np.ndarray,
                 out: np.ndarray) -> None:
    """``local`` (terms, chunks, chunk, 6): the in-chunk recursions; ``decay`` (terms, chunk):
    phi^1..phi^chunk; ``before`` (terms, chunks, 6): the state before each chunk; ``free``
    (n, 6): the walk's normal draws (becomes the free walk); ``rw`` (6): the free walk before
    (becomes the last one); ``b``, ``b4``, ``b2``: bound, 4 bound, 2 bound; ``white`` (n, 6):
    the white noise's normal draws. Fills ``out`` (n, 12): biases and white noises, the last
    sample's row first."""
    nt, nk, nc = local.shape[0], local.shape[1], local.shape[2]
    n = nk * nc
    for a in range(6):
        for j in range(1, n):
            free[j, a] = free[j - 1, a] + free[j, a]
    for j in range(n):
        kk, c = j // nc, j % nc
        row = n - 1 - j
        for a in range(6):
            s = local[0, kk, c, a] + decay[0, c] * before[0, kk, a]
            for t in range(1, nt):
                s = s + (local[t, kk, c, a] + decay[t, c] * before[t, kk, a])
            w = rw[a] + free[j, a] * walk_dt[a]
            free[j, a] = w
            y = w + b[a]
            m = np.fmod(y, b4[a])  # LLVM frem: C fmod, exact
            if m != 0.0:
                if (b4[a] < 0.0) != (m < 0.0):
                    m = m + b4[a]
            else:
                m = math.copysign(0.0, b4[a])
            f = (m if m < b2[a] else b4[a] - m) - b[a]
            out[row, a] = s + f
            out[row, 6 + a] = white[j, a] * sigma[a]
    for a in range(6):
        rw[a] = free[n - 1, a]


_finish: Any = None  # finish_block once compiled; False when it cannot be


def finish() -> Any:
    """The compiled :func:`finish_block` (compiled on first use), or None."""
    global _finish
    if _finish is None:
        try:
            z = np.zeros
            finish_block(z((1, 1, 2, 6)), z((1, 2)), z((1, 1, 6)), z((2, 6)), z(6), z(6),
                         np.ones(6), np.ones(6), np.ones(6), z((2, 6)), z(6), z((2, 12)))
            _finish = finish_block
        except Exception as exc:  # numba cannot compile it: the numpy form
            log.warning("the compiled IMU block is not available (%s); using numpy", exc)
            _finish = False
    return _finish or None
