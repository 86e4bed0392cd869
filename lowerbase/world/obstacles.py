"""Obstacles the map does not know: boxes a scenario places, and people walking a path.

Every obstacle is a prism from the floor to its height. A box is a pure function of simulated
time ``t`` [s]; a person is one of its own path time, which :class:`Obstacles` takes as ``t``
less the time the person waited for the robot (:mod:`lowerbase.world.people`): the same ``t``
gives the same shapes once the waits up to ``t`` are decided. Shapes are shapely
geometry in the map frame (a person's circle is a 64-gon: within 0.3 mm of the circle at
r = 0.25 m); :meth:`Obstacles.prisms_at` gives the exact form (polygon vertices or a circle)
for ray casting. A person walks the polyline ``path`` at ``speed`` from ``start`` [s] on; at
its end it stops, or with ``loop`` walks back to the first point and round again.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeAlias

import numpy as np
import shapely
from shapely.geometry import Point, Polygon

from lowerbase.errors import WorldError
from lowerbase.world.grid import FREE, OCCUPIED, OccupancyGrid
from lowerbase.world.people import Crowd

Point2 = tuple[float, float]
CIRCLE_SEGMENTS = 16  # per quarter circle (shapely's quad_segs)


def _finite(name: str, what: str, value: Any, positive: bool = False) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise WorldError(f"obstacle {name!r}: {what} must be a number, got {value!r}") from None
    if not math.isfinite(number) or (positive and number <= 0):
        raise WorldError(f"obstacle {name!r}: {what} must be a finite number"
                         f"{' > 0' if positive else ''}, got {value!r}")
    return number


def _point(name: str, what: str, value: Any) -> Point2:
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 2:
        raise WorldError(f"obstacle {name!r}: {what} must be [x, y], got {value!r}")
    return _finite(name, what, value[0]), _finite(name, what, value[1])


def _name(value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise WorldError(f"an obstacle needs a non-empty name, got {value!r}")
    return value


def _check_time(t: float) -> float:
    if not math.isfinite(t):
        raise WorldError(f"simulated time must be finite, got {t}")
    return t


@dataclass(frozen=True)
class Prism:
    """An obstacle's exact shape at one instant: ``polygon`` (N, 2) vertices or ``circle``
    (x, y, radius), from the floor to ``height`` [m]."""

    name: str
    height: float
    polygon: np.ndarray | None = None
    circle: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Box:
    """A box standing still: ``center`` (x, y) [m], ``size`` (length along ``yaw``, width) [m],
    ``yaw`` [rad], ``height`` [m]."""

    name: str
    center: Point2
    size: Point2
    yaw: float = 0.0
    height: float = 1.0

    def __post_init__(self) -> None:
        name = _name(self.name)
        object.__setattr__(self, "center", _point(name, "center", self.center))
        size = _point(name, "size", self.size)
        if min(size) <= 0:
            raise WorldError(f"obstacle {name!r}: size must be > 0 m each, got {self.size!r}")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "yaw", _finite(name, "yaw", self.yaw))
        object.__setattr__(self, "height", _finite(name, "height", self.height, positive=True))

    def corners(self) -> np.ndarray:
        """(4, 2) corners, counter-clockwise [m, map frame]."""
        half_l, half_w = self.size[0] / 2, self.size[1] / 2
        local = np.array([[half_l, half_w], [-half_l, half_w], [-half_l, -half_w],
                          [half_l, -half_w]])
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return local @ np.array([[c, s], [-s, c]]) + np.asarray(self.center)

    def shape_at(self, t: float) -> Polygon:
        _check_time(t)
        return Polygon(self.corners())

    def prism_at(self, t: float) -> Prism:
        _check_time(t)
        return Prism(self.name, self.height, polygon=self.corners())


@dataclass(frozen=True)
class Person:
    """A person (a cylinder of ``radius`` and ``height`` [m]) walking ``path`` at ``speed``
    [m/s] from time ``start`` [s]; with ``loop`` the path closes back to its first point."""

    name: str
    path: tuple[Point2, ...]
    speed: float = 1.2
    radius: float = 0.25
    height: float = 1.7
    loop: bool = False
    start: float = 0.0
    _cumulative: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        name = _name(self.name)
        if isinstance(self.path, (str, bytes)) or not isinstance(self.path, Sequence) \
                or len(self.path) == 0:
            raise WorldError(f"obstacle {name!r}: path must be a list of [x, y] points")
        path = tuple(_point(name, "path point", p) for p in self.path)
        speed = _finite(name, "speed", self.speed)
        if speed < 0:
            raise WorldError(f"obstacle {name!r}: speed must be >= 0 m/s, got {self.speed!r}")
        if not isinstance(self.loop, bool):
            raise WorldError(f"obstacle {name!r}: loop must be true or false, got {self.loop!r}")
        vertices = np.array((*path, path[0]) if self.loop else path)
        lengths = np.hypot(*np.diff(vertices, axis=0).T) if len(vertices) > 1 else np.zeros(0)
        if self.loop and speed > 0 and lengths.sum() <= 0:
            raise WorldError(f"obstacle {name!r}: a looping path needs two distinct points")
        object.__setattr__(self, "path", path)
        object.__setattr__(self, "speed", speed)
        object.__setattr__(self, "radius", _finite(name, "radius", self.radius, positive=True))
        object.__setattr__(self, "height", _finite(name, "height", self.height, positive=True))
        object.__setattr__(self, "start", _finite(name, "start", self.start))
        object.__setattr__(self, "_cumulative", np.concatenate([[0.0], np.cumsum(lengths)]))

    def position_at(self, t: float) -> Point2:
        """Where the person is at time ``t`` [m, map frame]."""
        walked = self.speed * max(_check_time(t) - self.start, 0.0)
        total = float(self._cumulative[-1])
        if total <= 0:
            return self.path[0]
        walked = walked % total if self.loop else min(walked, total)
        vertices = (*self.path, self.path[0]) if self.loop else self.path
        i = int(np.searchsorted(self._cumulative, walked, side="right")) - 1
        i = min(max(i, 0), len(vertices) - 2)
        seg = self._cumulative[i + 1] - self._cumulative[i]
        f = 0.0 if seg <= 0 else (walked - self._cumulative[i]) / seg
        (x0, y0), (x1, y1) = vertices[i], vertices[i + 1]
        return x0 + f * (x1 - x0), y0 + f * (y1 - y0)

    def shape_at(self, t: float) -> Polygon:
        return Point(self.position_at(t)).buffer(self.radius, quad_segs=CIRCLE_SEGMENTS)

    def prism_at(self, t: float) -> Prism:
        x, y = self.position_at(t)
        return Prism(self.name, self.height, circle=(x, y, self.radius))


Obstacle: TypeAlias = Box | Person


def _cells_under(shape: Any, grid: OccupancyGrid) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the cells that ``shape`` overlaps with positive area."""
    ox, oy, _ = grid.origin
    res = grid.resolution
    minx, miny, maxx, maxy = shape.bounds
    c0, r0 = max(math.floor((minx - ox) / res), 0), max(math.floor((miny - oy) / res), 0)
    c1 = min(math.floor((maxx - ox) / res), grid.width - 1)
    r1 = min(math.floor((maxy - oy) / res), grid.height - 1)
    if c1 < c0 or r1 < r0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    rows, cols = np.mgrid[r0:r1 + 1, c0:c1 + 1]
    rows, cols = rows.ravel(), cols.ravel()
    x0, y0 = ox + cols * res, oy + rows * res
    cells = shapely.box(x0, y0, x0 + res, y0 + res)
    shapely.prepare(shape)
    hit = shapely.intersects(shape, cells) & ~shapely.touches(shape, cells)
    return rows[hit], cols[hit]


class Obstacles:
    """A scenario's obstacles (unique names), all evaluated at one simulated time.

    People wait for the robot (:mod:`lowerbase.world.people`): ``crowd`` holds their waits,
    which whoever moves the robot advances; every shape and position here is read through
    them, so contact and sensors see the same people. :meth:`fresh` is a copy with no waits
    (one per simulated world)."""

    def __init__(self, items: Iterable[Obstacle] = ()) -> None:
        self.items: tuple[Obstacle, ...] = ()
        self.people: tuple[Person, ...] = ()
        self.crowd = Crowd(())
        self.replace(items)

    def replace(self, items: Iterable[Obstacle]) -> None:
        """These obstacles from now on (a box dropped or taken away); a person who stays (by
        name) keeps its waits."""
        new = tuple(items)
        names = [o.name for o in new]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise WorldError(f"obstacle names must be unique: {', '.join(dupes)} used twice")
        self.items = new
        self.people = tuple(o for o in new if isinstance(o, Person))
        self.crowd = self.crowd.keep(tuple(p.name for p in self.people))

    def fresh(self) -> Obstacles:
        """The same obstacles, nobody having waited yet."""
        return Obstacles(self.items)

    def __len__(self) -> int:
        return len(self.items)

    def path_time(self, person: Person, t: float) -> float:
        """The time on ``person``'s own schedule at ``t``: less the time it waited."""
        return t - self.crowd.waited(person.name, t)

    def position(self, person: Person, t: float) -> Point2:
        """Where ``person`` is at ``t``, its waits counted."""
        return person.position_at(self.path_time(person, _check_time(t)))

    def shape(self, o: Obstacle, t: float) -> Any:
        return o.shape_at(self.path_time(o, t) if isinstance(o, Person) else t)

    def prism(self, o: Obstacle, t: float) -> Prism:
        return o.prism_at(self.path_time(o, t) if isinstance(o, Person) else t)

    def shapes_at(self, t: float) -> list[tuple[str, Any]]:
        """(name, shapely geometry) of every obstacle at time ``t``."""
        return [(o.name, self.shape(o, t)) for o in self.items]

    def prisms_at(self, t: float) -> list[Prism]:
        return [self.prism(o, t) for o in self.items]

    def heights(self, grid: OccupancyGrid, t: float) -> np.ndarray:
        """(height, width) float array: the tallest obstacle over each cell [m], 0 if none."""
        out = np.zeros(grid.data.shape, np.float64)
        for o in self.items:
            rows, cols = _cells_under(self.shape(o, t), grid)
            out[rows, cols] = np.maximum(out[rows, cols], o.height)
        return out

    def overlay(self, grid: OccupancyGrid, t: float) -> OccupancyGrid:
        """The obstacles alone on ``grid``'s cells: 100 where one overlaps a cell, else 0."""
        data = np.where(self.heights(grid, t) > 0, OCCUPIED, FREE).astype(np.int8)
        return OccupancyGrid(data, grid.resolution, grid.origin)

    def merged(self, grid: OccupancyGrid, t: float) -> OccupancyGrid:
        """``grid`` with the obstacles' cells at time ``t`` marked occupied."""
        data = grid.data.copy()
        data[self.heights(grid, t) > 0] = OCCUPIED
        return OccupancyGrid(data, grid.resolution, grid.origin)


BOX_KEYS = {"kind", "name", "center", "size", "yaw", "height"}
PERSON_KEYS = {"kind", "name", "path", "speed", "radius", "height", "loop", "start"}


def obstacle_from_dict(spec: Mapping[str, Any]) -> Obstacle:
    """One obstacle from a scenario table: ``kind = "box"`` or ``"person"`` plus its fields."""
    kind = spec.get("kind")
    name = spec.get("name", "?")
    allowed = {"box": BOX_KEYS, "person": PERSON_KEYS}.get(str(kind))
    if allowed is None:
        raise WorldError(f"obstacle {name!r}: kind must be box or person, got {kind!r}")
    unknown = sorted(set(spec) - allowed)
    if unknown:
        raise WorldError(f"obstacle {name!r}: unknown field(s) {', '.join(unknown)} "
                         f"(a {kind} has {', '.join(sorted(allowed - {'kind'}))})")
    fields = {k: v for k, v in spec.items() if k != "kind"}
    try:
        return Box(**fields) if kind == "box" else Person(**fields)
    except TypeError as exc:  # a required field missing
        raise WorldError(f"obstacle {name!r}: {exc}") from None


def obstacles_from_dicts(specs: Iterable[Mapping[str, Any]]) -> Obstacles:
    return Obstacles(obstacle_from_dict(s) for s in specs)
