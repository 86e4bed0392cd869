"""Recovery behaviours, as move_base runs them between replans: :class:`BackOff`,
:class:`ClearCostmap` and :class:`Rotate`, in the order of :data:`ORDER`.

A robot can wedge itself where its footprint has no lethal-free motion along the plan (a
rectangular base turning in an aisle it fits only straight): the controller answers BLOCKED on
every tick, and replanning from the same pose gives the same plan. Before each replan the
navigator therefore backs the robot off: straight along its heading at ``speed`` for up to
``distance``, the way it came (back; forward when it was driving reversed) or the other way,
whichever keeps the robot's own footprint (without the costmap's padding, as a StepControl
move) off lethal cells and ends further from obstacles (the way it came on a tie); while it
moves, the sweep over the next ``lookahead`` must stay clear (when the footprint already touches
a lethal cell, the end of the back-off). When both ways look blocked before it moved, it
escalates once: the local marks in a ``resense_clear`` square around the robot are forgotten
(stale marks beside the robot that no ray clears), it waits for the next scan to mark what is
there and tries again. A turn that cannot start does the same.

move_base's own behaviours follow when blocked replans go on (``recovery_behaviors``, default
``ORDER``, one per replan): ``ClearCostmap`` conservative (the local marks outside a
``reset_distance`` square around the robot forgotten: stale marks of something gone that the
lidars no longer see), ``Rotate`` (a full turn in place while the footprint's sweep stays off
lethal cells: the lidars see all round again), ``ClearCostmap`` aggressive (every local mark
forgotten). No plan at all while the local costmap holds marks: its obstacle layer is reset
and the planner tried once more (:meth:`Recoveries.clear_for_plan`, move_base's recoveries
after a planner failure).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
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
    #: [m] both ways blocked before moving: forget the local marks in a square this wide
    #: around the robot, wait for the next scan to mark what is there, try once more
    #: (stale marks beside the robot, where no ray clears them; 0: never)
    resense_clear: float = 2.0


class BackOff:
    """One back-off at a time: :meth:`begin`, then :meth:`step` each tick until it says done."""

    def __init__(self, config: BackOffConfig | None = None) -> None:
        self.config = config or BackOffConfig()
        self._start: Pose | None = None
        self._t0 = 0.0
        self._sign = -1.0
        self._reversed = False
        self._chosen = False
        self.count = 0  #: back-offs begun (for the stats)
        self.flipped = 0  #: back-offs that went the other way (the way back was blocked)
        self.blocked = False  #: the last back-off ended before moving: both ways blocked

    @property
    def active(self) -> bool:
        return self._start is not None

    def begin(self, pose: Pose, now: float, reversed_driving: bool) -> None:
        self._start, self._t0 = pose, now
        self._reversed = reversed_driving
        self._sign = 1.0 if reversed_driving else -1.0
        self._chosen = False  # the direction is chosen at the first step (see step)
        self.blocked = False
        self.count += 1

    def restart(self, pose: Pose, now: float) -> None:
        """The same back-off again from ``pose`` (after a re-sense), its direction chosen anew."""
        self.begin(pose, now, self._reversed)
        self.count -= 1

    def cancel(self) -> None:
        self._start = None

    def step(self, pose: Pose, now: float, costs: np.ndarray, origin: tuple[float, float],
             footprint: FootprintCells, body: FootprintCells | None = None) -> float | None:
        """The linear speed [m/s] to command now, or None: the back-off is over (far enough,
        both ways blocked, or the timeout).

        The direction is chosen at the first step: of the two ways along the heading whose
        sweep over ``distance`` keeps the robot's ``body`` (its footprint without the
        costmap's padding; None: ``footprint``) off lethal cells, the one ending with the
        padded ``footprint`` on the lower cost (further from obstacles), the way it came on a
        tie. A skewed robot whose corner is at a wall behind it thus backs off forwards, into
        the free space, as a StepControl move would."""
        start, cfg = self._start, self.config
        if start is None:
            return None
        fp = body or footprint
        x, y, yaw = pose
        moved = math.hypot(x - start[0], y - start[1])
        if moved >= cfg.distance or now - self._t0 >= cfg.timeout:
            self._start = None
            return None
        if not self._chosen:
            best: tuple[float, float] | None = None
            for sign in (self._sign, -self._sign):
                if not self._clear(sign, pose, cfg.distance, costs, origin, fp):
                    continue
                end = footprint.max_cost(costs, origin, x + sign * cfg.distance * math.cos(yaw),
                                         y + sign * cfg.distance * math.sin(yaw), yaw)[0]
                if best is None or end < best[0]:
                    best = (float(end), sign)
            if best is None:
                self.blocked = True  # ended without moving: both ways blocked
                self._start = None
                return None
            self.flipped += best[1] != self._sign
            self._sign, self._chosen = best[1], True
        elif not self._clear(self._sign, pose, cfg.lookahead, costs, origin, fp):
            self._start = None
            return None
        return self._sign * cfg.speed

    def _clear(self, sign: float, pose: Pose, length: float, costs: np.ndarray,
               origin: tuple[float, float], footprint: FootprintCells) -> bool:
        """Whether the footprint's sweep ``sign``-wards (1 forward, -1 back) over ``length``
        stays off lethal cells; when it touches one already (the robot wedged, or the
        estimate off by a few cm in a tight aisle), whether the end of the sweep does."""
        x, y, yaw = pose
        c, sn = math.cos(yaw), math.sin(yaw)
        if footprint.max_cost(costs, origin, x, y, yaw)[0] >= LETHAL:
            s = np.array([length * sign])
        else:
            n = max(2, math.ceil(length / 0.025) + 1)
            s = np.linspace(0.0, length, n)[1:] * sign
        px, py = x + s * c, y + s * sn
        return not bool((footprint.max_cost(costs, origin, px, py, np.full_like(px, yaw))
                         >= LETHAL).any())


@dataclass(frozen=True)
class RotateConfig:
    speed: float = 0.5  #: [rad/s]
    lookahead: float = 0.2  #: [rad] the sweep ahead that must stay off lethal cells
    timeout: float = 25.0  #: [s] give up turning after this long


class Rotate:
    """rotate_recovery: one full turn in place, :meth:`begin` then :meth:`step` each tick until
    it says done (turned 2 pi, the sweep ahead would touch a lethal cell, or the timeout).
    Counter-clockwise, as rotate_recovery; clockwise when only that way has room to start."""

    def __init__(self, config: RotateConfig | None = None) -> None:
        self.config = config or RotateConfig()
        self._last: float | None = None
        self._turned = 0.0
        self._t0 = 0.0
        self._sign = 1.0
        self.count = 0  #: turns begun
        self.clockwise = 0  #: turns that went clockwise (no room counter-clockwise)
        self.blocked = False  #: the last turn ended before turning: its sweep was blocked

    @property
    def active(self) -> bool:
        return self._last is not None

    def begin(self, pose: Pose, now: float) -> None:
        self._last, self._turned, self._t0, self._sign = pose[2], 0.0, now, 1.0
        self.blocked = False
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

        def room(sign: float) -> bool:
            ahead = yaw + sign * np.linspace(0.0, cfg.lookahead, 5)[1:]
            return not bool((footprint.max_cost(costs, origin, np.full_like(ahead, x),
                                                np.full_like(ahead, y), ahead)
                             >= LETHAL).any())

        if room(self._sign):
            return self._sign * cfg.speed
        if self._turned < 1e-3 and self._sign > 0 and room(-1.0):
            self._sign = -1.0
            self.clockwise += 1
            return -cfg.speed
        self.blocked = self._turned < 1e-3  # could not start turning
        self._last = None
        return None


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
        #: waiting for a sensor update after clear_around: (updates then, pose, time)
        self._resense: tuple[int, str, float] | None = None
        self._resensed = False  #: clear_around done in this recovery already
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
        self._resensed = False
        self.back_off.blocked = self.rotate.blocked = False
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
        return self.back_off.active or self.rotate.active or self._resense is not None

    def cancel(self) -> None:
        self.back_off.cancel()
        self.rotate.cancel()
        self._resense = None

    def resense(self, pose: Pose, now: float, local: LayeredCostmap) -> bool:
        """A back-off that found both ways blocked before moving escalates once: the local
        marks in a ``resense_clear`` square around the robot are forgotten (clear_costmap's
        reset, but around the robot, where the conservative one keeps them), and the back-off
        starts again after the next sensor update has marked what is really there. True:
        escalated (the caller refreshes the costs; :meth:`step` holds still until then)."""
        size = self.back_off.config.resense_clear
        move = "back_off" if self.back_off.blocked else "rotate" if self.rotate.blocked else ""
        if not move or self._resensed or size <= 0:
            return False
        self.back_off.blocked = self.rotate.blocked = False
        self._resensed = True
        self.log.append("clear_around")
        local.clear_inside(pose[0], pose[1], size)
        self._resense = (local.stats.updates, move, now)
        return True

    def step(self, pose: Pose, now: float, costs: np.ndarray, origin: tuple[float, float],
             footprint: FootprintCells, local: LayeredCostmap | None = None,
             body: FootprintCells | None = None) -> tuple[float, float] | None:
        """(linear, angular) to command now, or None: no recovery runs (any more). ``body``:
        the robot's footprint without the costmap's padding, which the back-off keeps off
        lethal cells (None: ``footprint``)."""
        if self._resense is not None:
            updates, move, t0 = self._resense
            if local is not None and local.stats.updates <= updates \
                    and now - t0 < self.back_off.config.timeout:
                return (0.0, 0.0)  # standing still until a scan has marked what is there
            self._resense = None
            if move == "back_off":
                self.back_off.restart(pose, now)
            else:
                self.rotate.begin(pose, now)
                self.rotate.count -= 1  # the same turn, tried again
        if self.back_off.active:
            v = self.back_off.step(pose, now, costs, origin, footprint, body)
            return None if v is None else (v, 0.0)
        w = self.rotate.step(pose, now, costs, origin, footprint)
        return None if w is None else (0.0, w)
