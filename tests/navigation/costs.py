"""An inflated cost array for the navigation tests, built here with costmap_2d's inflation
formula (independent of lowerbase.navigation's costmap): 254 on occupied cells, 253 within the
inscribed radius, ``252 exp(-k (d - inscribed))`` out to the inflation radius, 0 beyond."""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import distance_transform_edt

from lowerbase.world.footprint import DEFAULT_FOOTPRINT, Footprint
from lowerbase.world.grid import OccupancyGrid

PADDED = DEFAULT_FOOTPRINT.padded(0.1)


def inscribed_radius(footprint: Footprint) -> float:
    return float(footprint.polygon.exterior.distance(footprint.polygon.centroid))


def inflate(grid: OccupancyGrid, footprint: Footprint = PADDED, inflation_radius: float = 1.0,
            scaling: float = 3.0) -> np.ndarray:
    occupied = grid.occupied()
    d = distance_transform_edt(~occupied) * grid.resolution
    ins = inscribed_radius(footprint)
    cost = np.zeros(occupied.shape, dtype=np.uint8)
    ring = (d > ins) & (d <= inflation_radius)
    cost[ring] = (252 * np.exp(-scaling * (d[ring] - ins))).astype(np.uint8)
    cost[(d <= ins) & ~occupied] = 253
    cost[occupied] = 254
    return cost


def free_grid(width_m: float, height_m: float, res: float = 0.05) -> OccupancyGrid:
    h, w = math.ceil(height_m / res), math.ceil(width_m / res)
    return OccupancyGrid(np.zeros((h, w), dtype=np.int8), res)
