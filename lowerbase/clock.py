"""The one time source of every model: injected, never read from the wall clock directly.

``RealClock`` follows ``time.monotonic``; ``SimClock`` is advanced by whoever drives the
simulation, so an hour of chassis time runs as fast as the CPU allows and tests are exact.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    """A monotonic time source in seconds."""

    def now(self) -> float:
        """Current time [s] (monotonic, arbitrary epoch)."""
        ...

    def sleep_until(self, deadline: float) -> None:
        """Block (real clock) or jump (simulated clock) until ``now() >= deadline``."""
        ...

    @property
    def is_simulated(self) -> bool:
        """True when time only advances when the simulation advances it."""
        ...


class RealClock:
    """Wall-clock time from ``time.monotonic``; ``sleep_until`` really sleeps."""

    is_simulated = False

    def __init__(self, stop_event: threading.Event | None = None) -> None:
        self._stop = stop_event

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, deadline: float) -> None:
        delay = deadline - time.monotonic()
        if delay <= 0:
            return
        if self._stop is not None:
            self._stop.wait(delay)
        else:
            time.sleep(delay)


class SimClock:
    """Simulated time: starts at ``start`` and moves only through ``advance``/``sleep_until``."""

    is_simulated = True

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)

    def now(self) -> float:
        return self._t

    def advance(self, dt: float) -> float:
        """Move time forward by ``dt`` [s] (>= 0) and return the new time."""
        if dt < 0:
            raise ValueError(f"cannot move a clock backwards (dt={dt})")
        self._t += dt
        return self._t

    def sleep_until(self, deadline: float) -> None:
        if deadline > self._t:
            self._t = float(deadline)
