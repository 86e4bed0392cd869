"""The one time source of every model: injected, never read from the wall clock directly.

``RealClock`` follows ``time.monotonic``; ``ScaledClock`` runs ``factor`` times as fast as it
(``lowerbase emulate --speed K``: paced, but K times real time); ``SimClock`` is advanced by
whoever drives the simulation, so an hour of chassis time runs as fast as the CPU allows and
tests are exact. :func:`real_seconds` turns a span of a clock's time into wall seconds (what a
``select``/``recv`` timeout needs).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
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


class ScaledClock:
    """Paced time running ``factor`` (> 0) times as fast as ``time.monotonic``: ``now()`` is
    ``factor`` x the monotonic seconds since construction; ``sleep_until`` really sleeps
    ``(deadline - now()) / factor`` wall seconds (or until ``stop_event`` is set).
    ``monotonic`` is injectable (tests)."""

    is_simulated = False

    def __init__(self, factor: float, stop_event: threading.Event | None = None, *,
                 monotonic: Callable[[], float] = time.monotonic,
                 wait: Callable[[float], object] | None = None) -> None:
        if not (factor > 0 and factor < float("inf")):
            raise ValueError(f"a clock's speed factor must be a finite number > 0, not {factor}")
        self.factor = float(factor)
        self._monotonic = monotonic
        self._t0 = monotonic()
        self._stop = stop_event
        self._wait = wait

    def now(self) -> float:
        return self.factor * (self._monotonic() - self._t0)

    def sleep_until(self, deadline: float) -> None:
        delay = (deadline - self.now()) / self.factor
        if delay <= 0:
            return
        if self._wait is not None:
            self._wait(delay)
        elif self._stop is not None:
            self._stop.wait(delay)
        else:
            time.sleep(delay)


def real_seconds(clock: Clock, span: float) -> float:
    """The wall seconds that ``span`` seconds of ``clock`` take (``span / factor`` on a
    :class:`ScaledClock`, ``span`` on any other clock)."""
    factor = getattr(clock, "factor", 1.0)
    return span / factor if isinstance(factor, (int, float)) and factor > 0 else span


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
