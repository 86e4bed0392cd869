"""The one seam between the world and the emulated robot, both ways.

- The world READS the robot's ground truth only through :class:`TruthSource`: ``sample()``
  gives a :class:`~lowerbase.world.truth_stream.TruthSample` (time, true pose and twist in the
  emulator's frame, contact). :class:`LoopTruth` is the in-process implementation over a
  :class:`~lowerbase.simloop.loop.SimLoop`; ``truth_stream.TruthReceiver`` carries the same
  samples across processes.
- The robot FEELS the world only through the firmware model's
  :class:`~lowerbase.firmware_model.truth.Surroundings`: :class:`WorldSurroundings` answers
  whether a move of the footprint is free of walls, the map's edge and obstacles, and keeps
  what was touched (:attr:`WorldSurroundings.contact`, :attr:`WorldSurroundings.events`).

The emulator's frame starts wherever the emulator put its truth (usually the origin); the
world places it on the map with a fixed transform ``map_from_truth`` (the robot's start pose),
so nothing is written into the emulator.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import shapely
from scipy.ndimage import distance_transform_edt

from lowerbase.world.footprint import DEFAULT_FOOTPRINT, Contact, Footprint, contact
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.localization.poses import Pose2D, compose
from lowerbase.world.obstacles import Box, Obstacles, Person
from lowerbase.world.people import CLEARANCE, STEP
from lowerbase.world.truth_stream import TruthSample

if TYPE_CHECKING:
    from lowerbase.simloop.loop import SimLoop

__all__ = ["ContactEvent", "LoopTruth", "PeopleFromTruth", "TruthSample", "TruthSource",
           "WorldSurroundings"]


def _wait_reach(person: Person) -> float:
    """[m] beyond its circle, how near a person may be to the footprint and still be decided
    to wait: CLEARANCE, at a step's end (a grid step decided up to STEP after the period)."""
    return CLEARANCE + person.speed * STEP


class TruthSource(Protocol):
    """Where the world gets the robot's ground truth (the emulator's frame, see module)."""

    def sample(self) -> TruthSample | None:
        """The newest sample, or None while none is known."""
        ...


class LoopTruth:
    """:class:`TruthSource` over a SimLoop in this process (``loop.mcu.truth``, read only)."""

    def __init__(self, loop: SimLoop) -> None:
        self.loop = loop

    def sample(self) -> TruthSample:
        tr = self.loop.mcu.truth
        return TruthSample(self.loop.now, tr.x, tr.y, tr.yaw, tr.v, tr.w, tr.blocked,
                           boot=self.loop.mcu.boot_counter)


@dataclass
class ContactEvent:
    """One stretch of contact: from ``start`` to ``end`` [s] (None while it lasts), what was
    touched, where first (map frame [m]), and whether the robot was stopped by it."""

    start: float
    touched: tuple[str, ...]
    point: tuple[float, float]
    end: float | None = None


class WorldSurroundings:
    """The firmware model's Surroundings for a map with obstacles (footprint contact).

    A move is allowed when the footprint at the new pose touches nothing, or when it was
    already touching (a person walked into the robot) and the move reduces the overlap. A
    cheap clearance test (distance transform of the walls, bounding circles of the obstacles)
    skips the polygon test wherever contact is impossible."""

    def __init__(self, grid: OccupancyGrid, obstacles: Obstacles | None = None,
                 footprint: Footprint = DEFAULT_FOOTPRINT,
                 map_from_truth: Pose2D = (0.0, 0.0, 0.0)) -> None:
        self.grid = grid
        self.obstacles = obstacles if obstacles is not None else Obstacles()
        self.footprint = footprint
        self.map_from_truth = map_from_truth
        self.contact: Contact | None = None  #: what the footprint touches (or was refused at)
        self.events: list[ContactEvent] = []
        self.checks = 0  #: full polygon tests made (the rest were cleared cheaply)
        occupied = grid.occupied()
        self._occupied = occupied
        self._clearance = (distance_transform_edt(~occupied) * grid.resolution
                           if occupied.any() else np.full(occupied.shape, math.inf))
        # the footprint's circle plus a cell diagonal (the EDT is measured between cell centres)
        self._radius = footprint.radius
        self._wall_margin = self._radius + grid.resolution * math.sqrt(2.0) + 1e-6

    def to_map(self, pose: Pose2D) -> Pose2D:
        return compose(self.map_from_truth, pose)

    def _may_touch(self, pose: Pose2D, t: float) -> bool:
        x, y, _ = pose
        g = self.grid
        ox, oy, _ = g.origin
        w, h = g.size_m
        r = self._radius
        if not (ox + r < x < ox + w - r and oy + r < y < oy + h - r):
            return True
        col = min(math.floor((x - ox) / g.resolution), g.width - 1)
        row = min(math.floor((y - oy) / g.resolution), g.height - 1)
        if self._clearance[row, col] <= self._wall_margin:
            return True
        for o in self.obstacles.items:
            if isinstance(o, Box):
                (cx, cy), reach = o.center, 0.5 * math.hypot(*o.size)
            elif isinstance(o, Person):
                (cx, cy), reach = self.obstacles.position(o, t), o.radius
            else:  # pragma: no cover - Obstacles holds only these
                return True
            if math.hypot(x - cx, y - cy) <= r + reach + 1e-6:
                return True
        return False

    def free_space(self, pose: Pose2D, t: float) -> tuple[float, float, float] | None:
        """How far the robot at ``pose`` (the emulator's truth frame) may move before the cheap
        test (``_may_touch``) could find anything: (static [m]: walls, the map's edge, boxes;
        moving [m]: people, as measured at ``t`` [s]; the fastest person's speed [m/s]).
        Negative: it may touch now. None: an obstacle it cannot bound.

        The wall clearance is a distance transform between cell centres, so it is 1-Lipschitz
        in them: a point ``d`` away lands in a cell whose clearance is at least this cell's
        minus ``d`` minus one cell diagonal (both points' offsets from their centres)."""
        x, y, _ = self.to_map(pose)
        g = self.grid
        ox, oy, _ = g.origin
        w, h = g.size_m
        r = self._radius
        static = min(x - ox - r, ox + w - r - x, y - oy - r, oy + h - r - y)
        if static > 0.0:
            col = min(math.floor((x - ox) / g.resolution), g.width - 1)
            row = min(math.floor((y - oy) / g.resolution), g.height - 1)
            static = min(static, float(self._clearance[row, col]) - self._wall_margin
                         - g.resolution * math.sqrt(2.0))
        moving, speed = math.inf, 0.0
        for o in self.obstacles.items:
            if isinstance(o, Box):
                (cx, cy), reach = o.center, 0.5 * math.hypot(*o.size)
                static = min(static, math.hypot(x - cx, y - cy) - (r + reach + 1e-6))
            elif isinstance(o, Person):  # no wait decided in the slack (people.py)
                (cx, cy) = self.obstacles.position(o, t)
                moving = min(moving, math.hypot(x - cx, y - cy)
                             - (r + o.radius + _wait_reach(o) + 1e-6))
                speed = max(speed, o.speed)
            else:  # pragma: no cover - Obstacles holds only these
                return None
        return static, moving, speed

    def polygon_free_space(self, pose: Pose2D, t: float, horizon: float = 0.25
                           ) -> tuple[float, float, float] | None:
        """As :meth:`free_space`, for the footprint itself (exact distances, each capped at
        ``horizon`` [m]): how far any point of the footprint at ``pose`` may move before the
        polygon test could find an overlap. For a robot standing near a wall (docked), where
        the circle's slack is gone. None: an obstacle it cannot bound, or it touches now."""
        x, y, yaw = self.to_map(pose)
        poly = self.footprint.at((x, y, yaw))
        g = self.grid
        ox, oy, _ = g.origin
        res = g.resolution
        minx, miny, maxx, maxy = poly.bounds
        c0 = max(math.floor((minx - horizon - ox) / res), 0)
        r0 = max(math.floor((miny - horizon - oy) / res), 0)
        c1 = min(math.floor((maxx + horizon - ox) / res), g.width - 1)
        r1 = min(math.floor((maxy + horizon - oy) / res), g.height - 1)
        w, h = g.size_m
        static = min(horizon, minx - ox, miny - oy, ox + w - maxx, oy + h - maxy)
        if c1 >= c0 and r1 >= r0:
            rows, cols = np.nonzero(self._occupied[r0:r1 + 1, c0:c1 + 1])
            if rows.size:
                x0, y0 = ox + (cols + c0) * res, oy + (rows + r0) * res
                cells = shapely.box(x0, y0, x0 + res, y0 + res)
                static = min(static, float(shapely.distance(poly, cells).min()))
        moving, speed = math.inf, 0.0
        for o in self.obstacles.items:
            if isinstance(o, Box):
                static = min(static, poly.distance(o.shape_at(t)))
            elif isinstance(o, Person):
                moving = min(moving, horizon,
                             poly.distance(self.obstacles.shape(o, t)) - _wait_reach(o))
                speed = max(speed, o.speed)
            else:  # pragma: no cover - Obstacles holds only these
                return None
        if min(static, moving) <= 0.0:
            return None
        return static, moving, speed

    def touching(self, pose: Pose2D, t: float) -> Contact | None:
        """What the footprint at ``pose`` (MAP frame) touches at time ``t``."""
        if not self._may_touch(pose, t):
            return None
        self.checks += 1
        return contact(pose, self.grid, self.obstacles, t, self.footprint)

    def advance_people(self, t: float, pose: Pose2D) -> None:
        """Decide the people's walks up to ``t`` [s] with the robot at ``pose`` (the emulator's
        truth frame): a person whose next step would come within ``CLEARANCE`` of the
        footprint waits (:mod:`lowerbase.world.people`). Idempotent for a time decided."""
        obs = self.obstacles
        if not obs.people or t < obs.crowd.decided_until:
            return
        x, y, yaw = self.to_map(pose)
        by_name = {p.name: p for p in obs.people}
        poly: list[Any] = []

        def blocked(name: str, t_eff: float) -> bool:
            person = by_name[name]
            px, py = person.position_at(t_eff)
            reach = person.radius + CLEARANCE
            if math.hypot(px - x, py - y) > self._radius + reach:
                return False
            if not poly:
                poly.append(self.footprint.at((x, y, yaw)))
            return bool(poly[0].distance(shapely.Point(px, py)) < reach)

        obs.crowd.advance(t, blocked)

    def allowed(self, pose_from: Pose2D, pose_to: Pose2D, t: float) -> bool:
        """Surroundings.allowed (poses in the emulator's truth frame); the people's walks are
        decided first, with the robot where it stands."""
        t = 0.0 if math.isnan(t) else t
        self.advance_people(t, pose_from)
        to = self.to_map(pose_to)
        hit = self.touching(to, t)
        ok = True
        if hit is not None:
            moved = pose_to != pose_from
            before = self.touching(self.to_map(pose_from), t) if moved else hit
            ok = moved and before is not None and hit.area < before.area - 1e-12
        self._record(hit, t)
        return ok

    def _record(self, hit: Contact | None, t: float) -> None:
        self.contact = hit
        last = self.events[-1] if self.events else None
        open_event = last if last is not None and last.end is None else None
        if hit is None:
            if open_event is not None:
                open_event.end = t
            return
        if open_event is not None and open_event.touched == hit.touched:
            return
        if open_event is not None:
            open_event.end = t
        self.events.append(ContactEvent(t, hit.touched, hit.point))


class PeopleFromTruth:
    """The people's waits in a process that reads the truth stream (the world node): advanced
    with every sample its receiver takes (the receiver's ``on_sample``, chained after a hook
    already there), else with each sample :meth:`read` is given. A lock of its own, taken
    only here (the receiver drains from the scan and the camera threads)."""

    def __init__(self, surroundings: WorldSurroundings, truth: Any) -> None:
        self.surroundings = surroundings
        self._lock = threading.Lock()
        receiver: Any = truth if hasattr(truth, "on_sample") \
            else getattr(truth, "receiver", None)
        self.each_sample = receiver is not None and hasattr(receiver, "on_sample")
        if receiver is not None and self.each_sample:
            inner = receiver.on_sample

            def on_sample(sample: TruthSample) -> None:
                if inner is not None:
                    inner(sample)
                self._advance(sample)

            receiver.on_sample = on_sample

    def read(self, sample: TruthSample) -> None:
        """A sample the node read (used when the truth has no per-sample hook)."""
        if not self.each_sample:
            self._advance(sample)

    def _advance(self, sample: TruthSample) -> None:
        with self._lock:
            self.surroundings.advance_people(sample.t, sample.pose)
