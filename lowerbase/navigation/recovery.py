"""Recovery behaviours, as move_base runs them between replans: :class:`BackOff`.

A robot can wedge itself where its footprint has no lethal-free motion along the plan (a
rectangular base turning in an aisle it fits only straight): the controller answers BLOCKED on
every tick, and replanning from the same pose gives the same plan. Before each replan the
navigator therefore backs the robot off the way it came: straight back (forward when it was
driving reversed) at ``speed`` for up to ``distance``, as long as the footprint's sweep over the
next ``lookahead`` stays off lethal cells (when the footprint already touches one, as long as the
end of the back-off is clear), then stops and replans from there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lowerbase.navigation.planner import LETHAL, FootprintCells

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
