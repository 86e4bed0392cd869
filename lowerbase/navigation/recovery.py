"""Recovery behaviours, as move_base runs them between replans: :class:`BackOff`,
:class:`ClearCostmap` and :class:`Rotate`, in the order of :data:`ORDER`.

A robot can wedge itself where its footprint has no lethal-free motion along the plan (a
rectangular base turning in an aisle it fits only straight): the controller answers BLOCKED on
every tick, and replanning from the same pose gives the same plan. Before each replan the
navigator therefore backs the robot off the way it came: straight back (forward when it was
driving reversed) at ``speed`` for up to ``distance``, as long as the footprint's sweep over the
next ``lookahead`` stays off lethal cells (when the footprint already touches one, as long as the
end of the back-off is clear), then stops and replans from there.

move_base's own behaviours follow when blocked replans go on (``ORDER``, one per replan):
``ClearCostmap`` conservative (the local marks outside a ``reset_distance`` square around the
robot forgotten: stale marks of something gone that the lidars no longer see), ``Rotate`` (a
full turn in place while the footprint's sweep stays off lethal cells: the lidars see all round
again), ``ClearCostmap`` aggressive (every local mark forgotten).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from lowerbase.navigation.planner import LETHAL, FootprintCells

if TYPE_CHECKING:
    from lowerbase.navigation.costmap import LayeredCostmap

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class BackOffConfig:
    distance: float = 0.3  #: [m] how far to back off at most
    speed: float = 0.1  #: [m/s]
    lookahead: float = 0.1  #: [m] the sweep that must stay off lethal cells
    timeout: float = 6.0  #: [s] give up backing off after this long (wheels slipping)


class BackOff:
    """One back-off at a time: :meth:`begin`, then :meth:`step` each tick until it says done."""

    def __init__(self, config: BackOffConfig | None = None) -> None:
        self.config = config or BackOffConfig()
        self._start: Pose | None = None
        self._t0 = 0.0
        self._sign = -1.0
        self.count = 0  #: back-offs begun (for the stats)

    @property
    def active(self) -> bool:
        return self._start is not None

    def begin(self, pose: Pose, now: float, reversed_driving: bool) -> None:
        self._start, self._t0 = pose, now
        self._sign = 1.0 if reversed_driving else -1.0
        self.count += 1

    def cancel(self) -> None:
        self._start = None

    def step(self, pose: Pose, now: float, costs: np.ndarray, origin: tuple[float, float],
             footprint: FootprintCells) -> float | None:
        """The linear speed [m/s] to command now, or None: the back-off is over (far enough,
        the way back is blocked too, or the timeout)."""
        start, cfg = self._start, self.config
        if start is None:
            return None
        x, y, yaw = pose
        moved = math.hypot(x - start[0], y - start[1])
        if moved >= cfg.distance or now - self._t0 >= cfg.timeout:
            self._start = None
            return None
        c, sn = math.cos(yaw), math.sin(yaw)
        if footprint.max_cost(costs, origin, x, y, yaw)[0] >= LETHAL:
            # already touching a lethal cell (the robot wedged, or the estimate off by a few
            # cm in a tight aisle): go on only if the end of the back-off is clear of them
            back = self._sign * (cfg.distance - moved)
            px, py = np.array([x + back * c]), np.array([y + back * sn])
        else:
            s = np.linspace(0.0, cfg.lookahead, 5)[1:] * self._sign
            px, py = x + s * c, y + s * sn
        if (footprint.max_cost(costs, origin, px, py, np.full_like(px, yaw)) >= LETHAL).any():
            self._start = None
            return None
        return self._sign * cfg.speed


@dataclass(frozen=True)
class RotateConfig:
    speed: float = 0.5  #: [rad/s]
    lookahead: float = 0.2  #: [rad] the sweep ahead that must stay off lethal cells
    timeout: float = 25.0  #: [s] give up turning after this long


class Rotate:
    """rotate_recovery: one full turn in place (counter-clockwise), :meth:`begin` then
    :meth:`step` each tick until it says done (turned 2 pi, the sweep ahead would touch a
    lethal cell, or the timeout)."""

    def __init__(self, config: RotateConfig | None = None) -> None:
        self.config = config or RotateConfig()
        self._last: float | None = None
        self._turned = 0.0
        self._t0 = 0.0
        self.count = 0  #: turns begun

    @property
    def active(self) -> bool:
        return self._last is not None

    def begin(self, pose: Pose, now: float) -> None:
        self._last, self._turned, self._t0 = pose[2], 0.0, now
        self.count += 1

    def cancel(self) -> None:
        self._last = None

    def step(self, pose: Pose, now: float, costs: np.ndarray, origin: tuple[float, float],
             footprint: FootprintCells) -> float | None:
        """The angular speed [rad/s] to command now, or None: the turn is over."""
        last, cfg = self._last, self.config
        if last is None:
            return None
        x, y, yaw = pose
        d = (yaw - last + math.pi) % (2.0 * math.pi) - math.pi
        self._turned += abs(d)
        self._last = yaw
        if self._turned >= 2.0 * math.pi - 0.05 or now - self._t0 >= cfg.timeout:
            self._last = None
            return None
        ahead = yaw + np.linspace(0.0, cfg.lookahead, 5)[1:]
        if (footprint.max_cost(costs, origin, np.full_like(ahead, x), np.full_like(ahead, y),
                               ahead) >= LETHAL).any():
            self._last = None
            return None
        return cfg.speed


@dataclass(frozen=True)
class ClearCostmap:
    """clear_costmap_recovery: ``reset_distance`` [m] the side of the square around the robot
    whose marks are kept (None: forget them all, the aggressive reset)."""

    reset_distance: float | None = 3.0


#: the navigator's reason while a recovery moves the robot
BACKING_OFF = "recovery: backing off the way the robot came, then replanning"
TURNING = "recovery: turning in place, then replanning"

#: what runs before the n-th blocked replan of a goal (n = 2, 3, ...; the first replans
#: straight away); a wedged robot (its footprint on a lethal cell) always backs off first
ORDER: tuple[str, ...] = ("back_off", "clear_conservative", "rotate", "clear_aggressive")


class Recoveries:
    """A navigator's recoveries: which one runs before a blocked replan (:meth:`choose`, in
    the order of :data:`ORDER`) and the one running (:meth:`step`)."""

    def __init__(self, back_off: BackOffConfig | None = None, rotate: RotateConfig | None = None,
                 clear: ClearCostmap | None = None) -> None:
        self.back_off = BackOff(back_off)
        self.rotate = Rotate(rotate)
        self.clear = clear or ClearCostmap()
        self.log: list[str] = []  #: every recovery chosen, oldest first

    @staticmethod
    def choose(replans: int, wedged: bool) -> str:
        """The recovery before the ``replans``-th blocked replan of a goal ('' none)."""
        if wedged:
            return "back_off"
        if replans < 2:
            return ""
        return ORDER[min(replans - 2, len(ORDER) - 1)]

    def begin(self, step: str, pose: Pose, now: float, reversed_driving: bool,
              local: LayeredCostmap) -> str:
        """Start recovery ``step`` (:meth:`choose`): a move (back off, turn; its reason is
        returned, :meth:`step` drives it) or a reset of the ``local`` costmap's marks, done
        at once ('' returned)."""
        self.log.append(step)
        if step == "back_off":
            self.back_off.begin(pose, now, reversed_driving)
            return BACKING_OFF
        if step == "rotate":
            self.rotate.begin(pose, now)
            return TURNING
        size = self.clear.reset_distance
        if step == "clear_conservative" and size is not None:
            local.clear_outside(pose[0], pose[1], size)
        else:
            local.clear()
        return ""

    @property
    def active(self) -> bool:
        return self.back_off.active or self.rotate.active

    def cancel(self) -> None:
        self.back_off.cancel()
        self.rotate.cancel()

    def step(self, pose: Pose, now: float, costs: np.ndarray, origin: tuple[float, float],
             footprint: FootprintCells) -> tuple[float, float] | None:
        """(linear, angular) to command now, or None: no recovery runs (any more)."""
        if self.back_off.active:
            v = self.back_off.step(pose, now, costs, origin, footprint)
            return None if v is None else (v, 0.0)
        w = self.rotate.step(pose, now, costs, origin, footprint)
        return None if w is None else (0.0, w)
