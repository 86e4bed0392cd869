"""FootprintCells.max_cost as the loop over heading bins it began as: the reference its batched
gather and its compiled kernel are compared with."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lowerbase.navigation.planner import LETHAL, NO_INFORMATION, FootprintCells


def reference_max_cost(fc: FootprintCells, costs: np.ndarray, origin: Sequence[float],
                       x: np.ndarray, y: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """The loop over heading bins (lowerbase before the batched gather)."""
    rows = np.floor((y - origin[1]) / fc.resolution).astype(np.int64)
    cols = np.floor((x - origin[0]) / fc.resolution).astype(np.int64)
    k = np.round(np.mod(yaw, 2.0 * np.pi) / (2.0 * np.pi) * fc.bins).astype(np.int64) % fc.bins
    out = np.empty(x.shape, dtype=np.int64)
    h, w = costs.shape
    for b in np.unique(k):
        sel = k == b
        dr, dc = fc.offsets[b]
        r = rows[sel][:, None] + dr[None, :]
        c = cols[sel][:, None] + dc[None, :]
        off = (r < 0) | (c < 0) | (r >= h) | (c >= w)
        vals = costs[np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)].astype(np.int64)
        vals[off] = LETHAL
        vals[vals == NO_INFORMATION] = 0
        out[sel] = vals.max(axis=1)
    return out
