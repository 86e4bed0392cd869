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
from collections.abc import Sequence
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
        self._chosen = False
        self.count = 0  #: back-offs begun (for the stats)
        self.flipped = 0  #: back-offs that went the other way (the way back was blocked)

    @property
    def active(self) -> bool:
        return self._start is not None

    def begin(self, pose: Pose, now: float, reversed_driving: bool) -> None:
        self._start, self._t0 = pose, now
        self._sign = 1.0 if reversed_driving else -1.0
        self._chosen = False  # the direction is chosen at the first step (see step)
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
        if self._clear(self._sign, pose, moved, costs, origin, footprint):
            self._chosen = True
            return self._sign * cfg.speed
        if not self._chosen and self._clear(-self._sign, pose, moved, costs, origin, footprint):
            # the way it came is blocked (a skewed robot's corner at a wall): back off the
            # other way, into the footprint's free space, as a StepControl move would
            self._sign, self._chosen = -self._sign, True
            self.flipped += 1
            return self._sign * cfg.speed
        self._start = None
        return None

    def _clear(self, sign: float, pose: Pose, moved: float, costs: np.ndarray,
               origin: tuple[float, float], footprint: FootprintCells) -> bool:
        """Whether the footprint's sweep ``sign``-wards (1 forward, -1 back) stays off lethal
        cells: over the next ``lookahead``; when it touches one already (the robot wedged, or
        the estimate off by a few cm in a tight aisle), at the end of the back-off."""
        cfg = self.config
        x, y, yaw = pose
        c, sn = math.cos(yaw), math.sin(yaw)
        if footprint.max_cost(costs, origin, x, y, yaw)[0] >= LETHAL:
            back = sign * (cfg.distance - moved)
            px, py = np.array([x + back * c]), np.array([y + back * sn])
        else:
            s = np.linspace(0.0, cfg.lookahead, 5)[1:] * sign
            px, py = x + s * c, y + s * sn
        return not bool((footprint.max_cost(costs, origin, px, py, np.full_like(px, yaw))
                         >= LETHAL).any())


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

#: the recovery behaviours there are (NavigatorConfig.recovery_behaviors picks and orders them)
BEHAVIORS = frozenset(("back_off", "clear_conservative", "rotate", "clear_aggressive"))


def check_behaviors(names: Sequence[str]) -> str:
    """'' or why ``names`` is no recovery order (unknown names, or none)."""
    if isinstance(names, str) or not names:
        return f"a non-empty list of {', '.join(sorted(BEHAVIORS))}, got {names!r}"
    unknown = [n for n in names if n not in BEHAVIORS]
    if unknown:
        return f"unknown {', '.join(map(repr, unknown))}; known: {', '.join(sorted(BEHAVIORS))}"
    return ""


class Recoveries:
    """A navigator's recoveries: which one runs before a blocked replan (:meth:`choose`, in
    the order of :data:`ORDER`) and the one running (:meth:`step`)."""

    def __init__(self, back_off: BackOffConfig | None = None, rotate: RotateConfig | None = None,
                 clear: ClearCostmap | None = None,
                 behaviors: Sequence[str] = ORDER) -> None:
        self.back_off = BackOff(back_off)
        self.rotate = Rotate(rotate)
        self.clear = clear or ClearCostmap()
        self.behaviors = tuple(behaviors)
        self.log: list[str] = []  #: every recovery chosen, oldest first

    @staticmethod
    def choose(replans: int, wedged: bool) -> str:
        """The recovery before the ``replans``-th blocked replan of a goal ('' none)."""
        if wedged:
            return "back_off"
        if replans < 2:
            return ""
        return ORDER[min(replans - 2, len(ORDER) - 1)]

    def pick(self, replans: int, wedged: bool) -> str:
        """:meth:`choose` on this navigator's ``behaviors``."""
        if wedged:
            return "back_off"
        if replans < 2:
            return ""
        order = self.behaviors
        return order[min(replans - 2, len(order) - 1)]

    def clear_for_plan(self, local: LayeredCostmap) -> bool:
        """No plan: forget every mark of the ``local`` costmap (its obstacle layer reset to
        free; the next scan marks what is there now). False: it held none (nothing to
        retry)."""
        layer = local.obstacle_layer
        if layer is None or not (layer.map.data != layer.map.default).any():
            return False
        self.log.append("clear_for_plan")
        local.clear()
        return True

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
