"""The robot's footprint and what it touches: map walls, the map's edge, obstacles.

The footprint is a simple polygon in ``base_link`` (x forward, y left, metres) around the
origin, as move_base's ``footprint`` parameter; the default is the seed's 8-point polygon of
the 0.8 x 0.6 m AMR, and :meth:`Footprint.padded` applies ``footprint_padding`` the way
costmap_2d does (each vertex moved outwards by the padding along x and along y).

Contact means a positive overlap area: a footprint that only shares an edge with a wall cell
does not touch it. A cell counts as wall when its value is >= 50 (unknown cells do not); the
map's edge counts as a wall, since nothing is known beyond it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import shapely
import yaml
from shapely.geometry import Point, Polygon

from lowerbase.errors import WorldError
from lowerbase.world.grid import OccupancyGrid

Pose = tuple[float, float, float]
Point2 = tuple[float, float]

#: the seed's example footprint (shared/seeds/000: /move_base/*/set_footprint)
DEFAULT_POINTS: tuple[Point2, ...] = (
    (-0.400, 0.253), (-0.353, 0.3), (0.353, 0.3), (0.4, 0.253),
    (0.4, -0.253), (0.353, -0.3), (-0.353, -0.3), (-0.4, -0.253),
)
#: the seed's footprint_padding [m]
DEFAULT_PADDING = 0.1
#: area below which an overlap is rounding noise, not contact [m^2]
MIN_OVERLAP = 1e-9


class ObstacleSource(Protocol):
    """What contact needs from obstacles: their named 2D shapes at simulated time ``t``."""

    def shapes_at(self, t: float) -> list[tuple[str, Any]]: ...


def check_pose(pose: Sequence[float]) -> Pose:
    """``pose`` as a finite (x, y, yaw) tuple, or :class:`WorldError`."""
    try:
        x, y, yaw = (float(v) for v in pose)
    except (TypeError, ValueError):
        raise WorldError(f"a pose is (x, y, yaw) numbers, got {pose!r}") from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise WorldError(f"pose must be finite numbers, got ({x}, {y}, {yaw})")
    return x, y, yaw


@dataclass(frozen=True)
class Footprint:
    """A robot footprint: a simple polygon around the origin of ``base_link`` [m]."""

    points: tuple[Point2, ...] = DEFAULT_POINTS
    polygon: Polygon = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        try:
            pts = tuple((float(x), float(y)) for x, y in self.points)
        except (TypeError, ValueError):
            raise WorldError(f"a footprint is a list of [x, y] points, got {self.points!r}"
                             ) from None
        if len(pts) < 3:
            raise WorldError(f"a footprint needs at least 3 points, got {len(pts)}")
        if not all(math.isfinite(v) for p in pts for v in p):
            raise WorldError(f"footprint points must be finite, got {pts}")
        poly = Polygon(pts)
        if not poly.is_valid or poly.area <= 0:
            raise WorldError("the footprint must be a simple polygon (edges must not cross), "
                             f"got {pts}")
        if not poly.contains(Point(0.0, 0.0)):
            raise WorldError("the footprint must surround the robot's origin (base_link), "
                             f"got {pts}")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "polygon", poly)

    @classmethod
    def parse(cls, text: str) -> Footprint:
        """From move_base's string form, e.g. ``[[-0.4, 0.253], [-0.353, 0.3], ...]``."""
        try:
            points = yaml.safe_load(text)
        except yaml.YAMLError:
            points = None
        if not isinstance(points, list) or not all(
                isinstance(p, list) and len(p) == 2 for p in points):
            raise WorldError(f"a footprint is written [[x1, y1], [x2, y2], ...], got {text!r}")
        return cls(tuple((p[0], p[1]) for p in points))

    def padded(self, padding: float = DEFAULT_PADDING) -> Footprint:
        """costmap_2d's padFootprint: every vertex moved by ``padding`` away from each axis."""
        if not (math.isfinite(padding) and padding >= 0):
            raise WorldError(f"footprint padding must be >= 0 m, got {padding}")
        return Footprint(tuple((x + math.copysign(padding, x) * (x != 0),
                                y + math.copysign(padding, y) * (y != 0))
                               for x, y in self.points))

    @property
    def radius(self) -> float:
        """Circumscribed radius [m] (the circle the robot sweeps turning in place)."""
        return max(math.hypot(x, y) for x, y in self.points)

    def at(self, pose: Sequence[float]) -> Polygon:
        """The footprint placed at ``pose`` (x, y, yaw) in the map frame."""
        x, y, yaw = check_pose(pose)
        c, s = math.cos(yaw), math.sin(yaw)
        pts = np.asarray(self.points)
        return Polygon(np.column_stack((x + c * pts[:, 0] - s * pts[:, 1],
                                        y + s * pts[:, 0] + c * pts[:, 1])))


DEFAULT_FOOTPRINT = Footprint()


@dataclass(frozen=True)
class Contact:
    """What the footprint touches: ``touched`` names ("wall", "map_edge", obstacle names),
    ``point`` the centroid of the overlap [m, map frame], ``area`` the overlap [m^2]."""

    touched: tuple[str, ...]
    point: Point2
    area: float


def _grid_bounds(grid: OccupancyGrid) -> Polygon:
    if grid.origin[2] != 0.0:
        raise WorldError(f"maps with a rotated origin (yaw {grid.origin[2]}) are not supported")
    ox, oy, _ = grid.origin
    w, h = grid.size_m
    return shapely.box(ox, oy, ox + w, oy + h)


def _wall_pieces(poly: Polygon, grid: OccupancyGrid) -> np.ndarray:
    """The overlaps of ``poly`` with occupied cells (only cells under its bounding box)."""
    ox, oy, _ = grid.origin
    res = grid.resolution
    minx, miny, maxx, maxy = poly.bounds
    c0 = max(math.floor((minx - ox) / res), 0)
    r0 = max(math.floor((miny - oy) / res), 0)
    c1 = min(math.floor((maxx - ox) / res), grid.width - 1)
    r1 = min(math.floor((maxy - oy) / res), grid.height - 1)
    if c1 < c0 or r1 < r0:
        return np.empty(0, dtype=object)
    rows, cols = np.nonzero(grid.data[r0:r1 + 1, c0:c1 + 1] >= 50)
    if rows.size == 0:
        return np.empty(0, dtype=object)
    x0 = ox + (cols + c0) * res
    y0 = oy + (rows + r0) * res
    cells = shapely.box(x0, y0, x0 + res, y0 + res)
    shapely.prepare(poly)
    hit = shapely.intersects(poly, cells) & ~shapely.touches(poly, cells)
    return np.asarray(shapely.intersection(poly, cells[hit]))


def contact(pose: Sequence[float], grid: OccupancyGrid, obstacles: ObstacleSource | None = None,
            t: float = 0.0, footprint: Footprint = DEFAULT_FOOTPRINT) -> Contact | None:
    """What the footprint at ``pose`` touches at simulated time ``t``, or None if nothing."""
    poly = footprint.at(pose)
    touched: list[str] = []
    pieces: list[Any] = []
    walls = _wall_pieces(poly, grid)
    if walls.size and shapely.area(walls).sum() > MIN_OVERLAP:
        touched.append("wall")
        pieces.extend(walls)
    outside = poly.difference(_grid_bounds(grid))
    if outside.area > MIN_OVERLAP:
        touched.append("map_edge")
        pieces.append(outside)
    for name, shape in (obstacles.shapes_at(t) if obstacles is not None else []):
        overlap = poly.intersection(shape)
        if overlap.area > MIN_OVERLAP:
            touched.append(name)
            pieces.append(overlap)
    if not touched:
        return None
    geoms = np.asarray(pieces, dtype=object)
    areas = shapely.area(geoms)
    centres = shapely.get_coordinates(shapely.centroid(geoms))
    total = float(areas.sum())
    cx, cy = (areas[:, None] * centres).sum(axis=0) / total
    return Contact(tuple(touched), (float(cx), float(cy)), total)


def validate_pose(pose: Sequence[float], grid: OccupancyGrid,
                  obstacles: ObstacleSource | None = None, t: float = 0.0,
                  footprint: Footprint = DEFAULT_FOOTPRINT, what: str = "the robot") -> Pose:
    """``pose`` if the footprint there is finite, on the map and touches nothing; else
    :class:`WorldError` saying what it touches."""
    checked = check_pose(pose)
    hit = contact(checked, grid, obstacles, t, footprint)
    if hit is not None:
        x, y, yaw = checked
        raise WorldError(
            f"{what} at ({x:.3f}, {y:.3f}, yaw {yaw:.3f}) would touch {' and '.join(hit.touched)}"
            f" near ({hit.point[0]:.2f}, {hit.point[1]:.2f}): place it on free floor")
    return checked
