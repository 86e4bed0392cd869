"""The shipped map library, drawn to scale: ``python -m lowerbase.world.mapgen [OUTDIR]``.

Every map is 0.05 m per cell with its origin at (0, 0, 0): coordinates below are metres in the
map frame. Walls are 0.2 m thick; space behind walls that no sensor can see is unknown (-1).
The robot the maps are drawn for is the seed's 0.8 x 0.6 m AMR, 1.0 x 0.8 m with the 0.1 m
footprint padding: every aisle is at least 1.5 m wide (the padded robot turns in place within
a 1.23 m circle).

- ``empty_room``: a 10 x 8 m room, nothing inside; one niche in the north wall so that the room
  has no 180-degree symmetry; the charger on the west wall.
- ``corridor_loop``: a 2 m wide corridor around a 19.6 x 9.6 m block; the north, east and west
  legs have pilasters at irregular spacing and the block has one chamfered corner, but the
  south leg is deliberately featureless for 19.6 m (a localizer cannot tell where along it it
  is once the corners are out of lidar range).
- ``warehouse`` (the default): 30 x 20 m; an office in the north-west corner, a staging area
  with pallets, two blocks of 1 m deep rack rows with 1.5 m aisles (block B has one row fewer
  and a cross gap), a few pillars, the charging station on the south wall.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
from skimage.draw import polygon as draw_polygon

from lowerbase.world.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from lowerbase.world.maps import MAP_NAMES, maps_dir, write_map
from lowerbase.world.places import Charger, Places, places_path, write_places

RESOLUTION = 0.05
WALL = 0.2


class Canvas:
    """A grid being drawn in map-frame metres (origin (0, 0), row 0 at y = 0)."""

    def __init__(self, width_m: float, height_m: float, fill: int = UNKNOWN) -> None:
        self.data = np.full((self._cells(height_m), self._cells(width_m)), fill, np.int8)

    @staticmethod
    def _cells(metres: float) -> int:
        return round(metres / RESOLUTION)

    def rect(self, x0: float, y0: float, x1: float, y1: float, value: int = OCCUPIED) -> None:
        """Fill the axis-aligned rectangle [x0, x1] x [y0, y1] (edges on cell boundaries)."""
        self.data[self._cells(y0):self._cells(y1), self._cells(x0):self._cells(x1)] = value

    def polygon(self, points: Iterable[tuple[float, float]], value: int = OCCUPIED) -> None:
        """Fill the cells whose centres lie inside the polygon (scikit-image's rasteriser)."""
        xs, ys = np.array(list(points), float).T
        rows, cols = draw_polygon(ys / RESOLUTION - 0.5, xs / RESOLUTION - 0.5, self.data.shape)
        self.data[rows, cols] = value

    def room(self, x0: float, y0: float, x1: float, y1: float) -> None:
        """Walls of thickness WALL whose outer edge is the rectangle, free inside."""
        self.rect(x0, y0, x1, y1, OCCUPIED)
        self.rect(x0 + WALL, y0 + WALL, x1 - WALL, y1 - WALL, FREE)

    def grid(self) -> OccupancyGrid:
        return OccupancyGrid(self.data.copy(), RESOLUTION, (0.0, 0.0, 0.0))


def empty_room() -> OccupancyGrid:
    c = Canvas(10.0, 8.6)
    c.room(0.0, 0.0, 10.0, 8.0)
    # a 1.5 m wide, 0.4 m deep niche in the north wall, off centre
    c.rect(6.3, 7.8, 8.2, 8.6, OCCUPIED)
    c.rect(6.5, 7.8, 8.0, 8.4, FREE)
    c.rect(0.2, 3.7, 0.5, 4.3)                     # the charger on the west wall
    return c.grid()


CORRIDOR_PILASTERS = (  # (x0, y0, x1, y1): 0.5 m wide, 0.3 m deep
    (3.5, 13.5, 4.0, 13.8), (7.0, 13.5, 7.5, 13.8), (12.5, 13.5, 13.0, 13.8),
    (14.0, 13.5, 14.5, 13.8), (19.5, 13.5, 20.0, 13.8),             # north leg, outer wall
    (21.8, 4.5, 22.1, 5.0), (21.8, 9.0, 22.1, 9.5),                  # east leg, block wall
    (0.2, 4.5, 0.5, 5.0),                                            # west leg, outer wall
)


def corridor_loop() -> OccupancyGrid:
    c = Canvas(24.0, 14.0)
    c.room(0.0, 0.0, 24.0, 14.0)
    # the inner block: 0.2 m walls, unknown inside, its north-east corner chamfered (1 m)
    outer = [(2.2, 2.2), (21.8, 2.2), (21.8, 10.8), (20.8, 11.8), (2.2, 11.8)]
    inner = [(2.4, 2.4), (21.6, 2.4), (21.6, 10.72), (20.72, 11.6), (2.4, 11.6)]
    c.polygon(outer, OCCUPIED)
    c.polygon(inner, UNKNOWN)
    for x0, y0, x1, y1 in CORRIDOR_PILASTERS:
        c.rect(x0, y0, x1, y1)
    c.rect(0.2, 7.7, 0.5, 8.3)                     # the charger on the west leg
    return c.grid()


#: rack rows (x0, y0, x1, y1): 1 m deep, 1.5 m aisles between rows
WAREHOUSE_RACKS = (
    # block A: six rows, the last one shorter
    (8.0, 3.0, 17.0, 4.0), (8.0, 5.5, 17.0, 6.5), (8.0, 8.0, 17.0, 9.0),
    (8.0, 10.5, 17.0, 11.5), (8.0, 13.0, 17.0, 14.0), (8.0, 15.5, 14.0, 16.5),
    # block B: five rows, the middle one split by a 1.5 m cross gap
    (19.5, 3.0, 28.0, 4.0), (19.5, 5.5, 28.0, 6.5), (19.5, 8.0, 23.0, 9.0),
    (24.5, 8.0, 28.0, 9.0), (19.5, 10.5, 28.0, 11.5), (19.5, 13.0, 28.0, 14.0),
)
WAREHOUSE_PILLARS = ((7.0, 8.0), (18.25, 6.0), (18.25, 12.5), (25.0, 18.0), (14.0, 18.5))
WAREHOUSE_PALLETS = ((1.0, 6.0, 2.2, 6.8), (1.0, 9.5, 2.2, 10.3), (4.5, 11.0, 5.3, 12.2))
WAREHOUSE_CHARGER = (3.0, 0.2, 3.6, 0.5)
#: aisle centre lines (y) of each block and the x range where the aisle is open on both sides
WAREHOUSE_AISLES = {"A": ((4.75, 7.25, 9.75, 12.25, 14.75), (8.0, 17.0)),
                    "B": ((4.75, 7.25, 9.75, 12.25), (19.5, 28.0))}


def warehouse() -> OccupancyGrid:
    c = Canvas(30.0, 20.0)
    c.room(0.0, 0.0, 30.0, 20.0)
    # the office in the north-west corner, a 1.2 m door in its south wall, a desk inside
    c.rect(0.2, 14.8, 6.2, 15.0)
    c.rect(6.0, 14.8, 6.2, 19.8)
    c.rect(2.0, 14.8, 3.2, 15.0, FREE)
    c.rect(1.0, 17.5, 2.6, 18.3)
    for rack in WAREHOUSE_RACKS:
        c.rect(*rack)
    for x, y in WAREHOUSE_PILLARS:
        c.rect(x - 0.2, y - 0.2, x + 0.2, y + 0.2)
    for pallet in WAREHOUSE_PALLETS:
        c.rect(*pallet)
    c.rect(*WAREHOUSE_CHARGER)
    return c.grid()


WEST, SOUTH = math.pi, -math.pi / 2


def empty_room_places() -> Places:
    return Places(storage={"R1": (8.0, 2.0, 0.0), "R2": (8.0, 6.0, 0.0)},
                  charger=Charger((1.0, 4.0, WEST), (2.0, 4.0, WEST)),
                  poses={"start": (5.0, 4.0, 0.0)})


def corridor_loop_places() -> Places:
    # the west leg is 2 m wide: the approach pose is only 0.4 m before the docked pose
    return Places(storage={"C1": (12.0, 1.2, 0.0), "C2": (12.0, 12.8, math.pi),
                           "C3": (22.8, 7.0, math.pi / 2)},
                  charger=Charger((1.0, 8.0, WEST), (1.4, 8.0, WEST)),
                  poses={"start": (6.0, 1.2, 0.0)})


#: storage points along each aisle (x), facing east; mark_no "<block><aisle>-<slot>"
WAREHOUSE_SLOTS = {"A": (9.5, 12.5, 15.5), "B": (21.0, 26.5)}


def warehouse_places() -> Places:
    storage = {}
    for block, (centres, _) in WAREHOUSE_AISLES.items():
        for aisle, y in enumerate(centres, start=1):
            for slot, x in enumerate(WAREHOUSE_SLOTS[block], start=1):
                storage[f"{block}{aisle}-{slot:02d}"] = (x, y, 0.0)
    cx = (WAREHOUSE_CHARGER[0] + WAREHOUSE_CHARGER[2]) / 2
    return Places(storage=storage, charger=Charger((cx, 1.0, SOUTH), (cx, 2.0, SOUTH)),
                  poses={"start": (4.0, 4.0, 0.0), "office": (4.0, 17.0, 0.0)})


GENERATORS: dict[str, tuple[Callable[[], OccupancyGrid], Callable[[], Places]]] = {
    "empty_room": (empty_room, empty_room_places),
    "corridor_loop": (corridor_loop, corridor_loop_places),
    "warehouse": (warehouse, warehouse_places),
}
assert tuple(sorted(GENERATORS)) == MAP_NAMES


def write_library(outdir: Path) -> list[Path]:
    """Write every map (YAML + PGM + places) into ``outdir``; returns the files written."""
    outdir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, (make_map, make_places) in GENERATORS.items():
        yaml_path = write_map(make_map(), outdir / f"{name}.yaml")
        written += [yaml_path, outdir / f"{name}.pgm"]
        written.append(write_places(make_places(), places_path(yaml_path),
                                    f"Named places of {name}.yaml: poses [x m, y m, yaw rad], "
                                    "map frame (python -m lowerbase.world.mapgen)"))
    return written


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    outdir = Path(args[0]) if args else maps_dir()
    for path in write_library(outdir):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
