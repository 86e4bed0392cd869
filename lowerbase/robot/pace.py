"""How fast the lockstep robot's simulated time runs against the wall: :class:`Pacer`.

``--speed K`` caps simulated seconds per wall second at K (``max``: no cap). The pacer never
makes up for lost time: when the host could not keep K (the robot's work took longer), its
reference moves on, so simulated time has slowed down and no burst follows; nothing else
changes, since the robot's parts run on simulated time alone. :meth:`Pacer.factor` is the
achieved speed over the last :data:`WINDOW` wall seconds (the status line), ``behind`` counts
the periods that could not keep K.
"""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Callable

WINDOW = 5.0  #: [s] of wall time the achieved factor is measured over
#: [s] of wall time behind K after which the pacer gives up the time (no catch-up burst)
SLACK = 0.05


class Pacer:
    """``wait(sim)`` before simulated time ``sim`` [s] begins; ``speed`` None: no cap."""

    def __init__(self, speed: float | None, *, window: float = WINDOW,
                 monotonic: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if speed is not None and not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be > 0 or None, got {speed!r}")
        self.speed = speed
        self.window = window
        self._monotonic = monotonic
        self._sleep = sleep
        self._ref: tuple[float, float] | None = None  #: (wall, sim) K is kept from
        self._seen: collections.deque[tuple[float, float]] = collections.deque()
        self.behind = 0  #: times the host could not keep K (simulated time slowed down)

    def restart(self) -> None:
        """Forget the reference (after a pause): the next ``wait`` starts afresh."""
        self._ref = None
        self._seen.clear()

    def wait(self, sim: float) -> None:
        wall = self._monotonic()
        if self._ref is None:
            self._ref = (wall, sim)
        elif self.speed is not None:
            due = self._ref[0] + (sim - self._ref[1]) / self.speed
            if due > wall:
                self._sleep(due - wall)
                wall = due
            elif wall - due > SLACK:
                self.behind += 1
                self._ref = (wall, sim)
        self._note(wall, sim)

    def _note(self, wall: float, sim: float) -> None:
        seen = self._seen
        seen.append((wall, sim))
        while len(seen) > 2 and wall - seen[1][0] >= self.window:
            seen.popleft()

    def factor(self) -> float | None:
        """Simulated seconds per wall second over the window (None before it can tell)."""
        if len(self._seen) < 2:
            return None
        (w0, s0), (w1, s1) = self._seen[0], self._seen[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else None
