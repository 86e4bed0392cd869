"""People wait for the robot: each person's waits, the one record both contact and sensors read.

A person walks its path on the simulated clock (:class:`~lowerbase.world.obstacles.Person`);
here it also waits where its next step would come within ``CLEARANCE`` of the robot's
footprint. Whether it walks is decided on a fixed grid of simulated time (every ``STEP`` s,
at multiples of ``STEP``) from the robot's true pose at that instant (:meth:`Waits.advance`,
called by whoever moves the robot: the emulator's contact before each period, the world before
each of its periods). The waits are kept as intervals, so a person's position at any time
already decided (a scan cast later at its own stamp) is exact: its walked distance is
``speed * (t - start - time waited before t)``. The path is never left: a person stops and goes
on, it does not step round.
"""

from __future__ import annotations

import math
from collections.abc import Callable

#: [s] the grid on which people decide to walk or wait (the truth stream's period)
STEP = 0.02
#: [m] a person stops this far from the robot's footprint
CLEARANCE = 0.05


class Waits:
    """One person's waits: closed intervals [a, b) and the one still open (``since``)."""

    def __init__(self) -> None:
        self.intervals: list[tuple[float, float]] = []
        self.since: float | None = None  #: waiting since then, not yet decided to walk on

    def waited(self, t: float) -> float:
        """[s] time spent waiting before ``t`` (an open wait counts up to ``t``)."""
        total = 0.0
        for a, b in self.intervals:
            if a >= t:
                break
            total += min(b, t) - a
        if self.since is not None and t > self.since:
            total += t - self.since
        return total

    def wait(self, t0: float) -> None:
        if self.since is None:
            self.since = t0

    def walk(self, t0: float) -> None:
        if self.since is not None:
            if t0 > self.since:
                self.intervals.append((self.since, t0))
            self.since = None


class Crowd:
    """The waits of every person of a scenario, advanced on the ``STEP`` grid."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self.waits = {n: Waits() for n in names}
        self._k: int | None = None  #: the next grid step to decide

    def keep(self, names: tuple[str, ...]) -> Crowd:
        """A crowd of ``names``: the waits of those already here, decided as far as now."""
        out = Crowd(names)
        for n in names:
            if n in self.waits:
                out.waits[n] = self.waits[n]
        out._k = self._k
        return out

    @property
    def decided_until(self) -> float:
        """[s] simulated time up to which the walks are decided (-inf before the first)."""
        return -math.inf if self._k is None else self._k * STEP

    def waited(self, name: str, t: float) -> float:
        w = self.waits.get(name)
        return 0.0 if w is None else w.waited(t)

    def advance(self, t: float, blocked: Callable[[str, float], bool]) -> None:
        """Decide every grid step that starts at or before ``t``: ``blocked(name, t_eff)``
        says whether that person at its own path time ``t_eff`` (the step's end less the time
        it waited) would be too near the robot (as it stands now); then it waits over the step.
        The first call starts the grid at ``t``."""
        if not self.waits or not math.isfinite(t):
            return
        if self._k is None:
            self._k = math.floor(t / STEP + 1e-9)
        while self._k * STEP <= t + 1e-9:
            t0 = self._k * STEP
            for name, w in self.waits.items():
                if blocked(name, t0 + STEP - w.waited(t0)):
                    w.wait(t0)
                else:
                    w.walk(t0)
            self._k += 1
