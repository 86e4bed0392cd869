"""The costs the Navigator plans and drives on: the global costmap with the local costmap's
marks pasted in, and per navigation mode a keep-out around new obstacles.

The local costmap's window lies on the map's cell grid (see ``costmap``), so it is pasted into
the global grid by a cell offset, max-combined. "New" obstacles are the local costmap's LETHAL
cells farther than ``static_margin`` from the map's own obstacles (walls the scan also sees are
not new); planning keeps the mode's clearance from them by making every cell within it
INSCRIBED (impassable to the planner)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import distance_transform_edt

from lowerbase.navigation.costmap import LayeredCostmap
from lowerbase.navigation.planner import INSCRIBED, LETHAL


class CombinedCosts:
    """Global costs + local marks; rebuilt by :meth:`refresh` after a local update."""

    def __init__(self, global_cm: LayeredCostmap, local_cm: LayeredCostmap,
                 static_margin: float = 0.15) -> None:
        self.global_cm = global_cm
        self.local_cm = local_cm
        self.static_margin = static_margin
        self.resolution = global_cm.resolution
        self.origin = global_cm.origin
        self._static_dist: np.ndarray | None = None
        self.costs = np.array(global_cm.costs)
        self.window: tuple[slice, slice, slice, slice] | None = None
        self.new_obstacles = np.zeros((0, 0), dtype=bool)
        self.version = 0

    def invalidate_static(self) -> None:
        """The global costmap changed (a new footprint): recompute what is the map's."""
        self._static_dist = None

    def _static(self) -> np.ndarray:
        if self._static_dist is None:
            lethal = np.asarray(self.global_cm.costs) == LETHAL
            self._static_dist = (distance_transform_edt(~lethal) * self.resolution
                                 ).astype(np.float32)
        return self._static_dist

    def refresh(self) -> None:
        """Rebuild from both costmaps (after a local update, clear or enable)."""
        base = np.asarray(self.global_cm.costs)
        costs = np.array(base)
        local = np.asarray(self.local_cm.costs)
        res = self.resolution
        lo = self.local_cm.origin
        c0 = round((lo[0] - self.origin[0]) / res)
        r0 = round((lo[1] - self.origin[1]) / res)
        h, w = costs.shape
        lh, lw = local.shape
        gr0, gc0 = max(r0, 0), max(c0, 0)
        gr1, gc1 = min(r0 + lh, h), min(c0 + lw, w)
        self.window = None
        self.new_obstacles = np.zeros((0, 0), dtype=bool)
        if gr1 > gr0 and gc1 > gc0:
            gs = (slice(gr0, gr1), slice(gc0, gc1))
            ls = (slice(gr0 - r0, gr1 - r0), slice(gc0 - c0, gc1 - c0))
            np.maximum(costs[gs], local[ls], out=costs[gs])
            self.window = (gs[0], gs[1], ls[0], ls[1])
            self.new_obstacles = (local[ls] == LETHAL) & \
                (self._static()[gs] > self.static_margin)
        self.costs = costs
        self.version += 1

    def planning_costs(self, clearance: float) -> np.ndarray:
        """The costs with every cell within ``clearance`` [m] of a new obstacle INSCRIBED."""
        if self.window is None or not self.new_obstacles.any():
            return self.costs
        rows, cols, _, _ = self.window
        pad = int(np.ceil(clearance / self.resolution)) + 1
        h, w = self.costs.shape
        r0, r1 = max(rows.start - pad, 0), min(rows.stop + pad, h)
        c0, c1 = max(cols.start - pad, 0), min(cols.stop + pad, w)
        mask = np.zeros((r1 - r0, c1 - c0), dtype=bool)
        mask[rows.start - r0:rows.stop - r0, cols.start - c0:cols.stop - c0] = \
            self.new_obstacles
        near = distance_transform_edt(~mask) * self.resolution <= clearance
        out = np.array(self.costs)
        sub = out[r0:r1, c0:c1]
        sub[near & (sub < INSCRIBED)] = INSCRIBED
        return out
