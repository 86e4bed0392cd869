"""The occupancy grid: one 2D map representation for maps, sensors, costmaps and localization.

Conventions are ROS's (nav_msgs/OccupancyGrid, map_server): cell ``(row, col)`` of ``data``
covers the square whose lower-left corner is ``origin + (col, row) * resolution`` in the map
frame, row 0 is the lowest y (the *bottom* of the image as map_server loads it), values are
0 (free) .. 100 (occupied) with -1 unknown. The origin's yaw is the map's rotation; lowerbase's
maps use yaw 0 and the sensors require it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lowerbase.errors import MapError

FREE = 0
OCCUPIED = 100
UNKNOWN = -1


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A 2D occupancy map.

    ``data``: int8 array of shape (height, width), row 0 at the lowest y;
    ``resolution``: [m/cell]; ``origin``: (x [m], y [m], yaw [rad]) of cell (0, 0)'s corner.
    """

    data: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise MapError(f"map resolution must be a positive number of metres, "
                           f"got {self.resolution!r}")
        if self.data.ndim != 2 or self.data.size == 0:
            raise MapError(f"map data must be a non-empty 2D array, got shape {self.data.shape}")
        if not all(math.isfinite(v) for v in self.origin):
            raise MapError(f"map origin must be finite, got {self.origin!r}")
        if self.data.dtype != np.int8:
            object.__setattr__(self, "data", self.data.astype(np.int8))

    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) [m]."""
        return self.width * self.resolution, self.height * self.resolution

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) [m] of the map's area in the map frame."""
        ox, oy, _ = self.origin
        w, h = self.size_m
        return ox, oy, ox + w, oy + h

    def contains(self, x: float, y: float) -> bool:
        """Whether the map-frame point (x, y) [m] lies on the map (NaN: no)."""
        x0, y0, x1, y1 = self.extent
        return x0 <= x < x1 and y0 <= y < y1

    def occupied(self, threshold: int = 50) -> np.ndarray:
        """Boolean mask of cells at or above ``threshold`` (unknown cells are not occupied)."""
        return self.data >= threshold

    def world_to_cell(self, x: np.ndarray | float, y: np.ndarray | float
                      ) -> tuple[np.ndarray, np.ndarray]:
        """(col, row) integer indices of map-frame points [m] (may lie outside the grid)."""
        ox, oy, _ = self.origin
        col = np.floor((np.asarray(x) - ox) / self.resolution).astype(np.int64)
        row = np.floor((np.asarray(y) - oy) / self.resolution).astype(np.int64)
        return col, row

    def cell_to_world(self, col: np.ndarray | int, row: np.ndarray | int
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Map-frame centre [m] of cells."""
        ox, oy, _ = self.origin
        return (ox + (np.asarray(col) + 0.5) * self.resolution,
                oy + (np.asarray(row) + 0.5) * self.resolution)

    def inside(self, col: np.ndarray, row: np.ndarray) -> np.ndarray:
        return (col >= 0) & (col < self.width) & (row >= 0) & (row < self.height)
