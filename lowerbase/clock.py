"""The one time source of every model: injected, never read from the wall clock directly.

``RealClock`` follows ``time.monotonic``; ``ScaledClock`` runs ``factor`` times as fast as it
(``lowerbase emulate --speed K``: paced, but K times real time); ``SimClock`` is advanced by
whoever drives the simulation, so an hour of chassis time runs as fast as the CPU allows and
tests are exact. :func:`real_seconds` turns a span of a clock's time into wall seconds (what a
``select``/``recv`` timeout needs).
"""

from __future__ import annotations

import logging
import math
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


#: how far [s] a paced loop may run behind its reference clock and still catch up, period by
#: period; beyond it the loop's time slips (:class:`PacedClock`)
CATCH_UP = 0.1
#: at most one slip warning per this many seconds of the reference clock
SLIP_WARN_EVERY = 10.0
#: [s] a wait shorter than this is due (:meth:`PacedClock.until_due`)
DUE_WITHIN = 1e-9


class WarnLimiter:
    """A warning said at most once per ``period`` [s] of the caller's clock, with what happened
    since the last one: :meth:`take` counts an event (and the largest ``value`` seen) and,
    when a warning is due (the first event, then the first at least ``period`` after the last
    warning), returns (events, largest value) since that warning and starts counting anew;
    None otherwise."""

    def __init__(self, period: float) -> None:
        self.period = float(period)
        self._said: float | None = None
        self._count = 0
        self._worst = -math.inf

    def take(self, now: float, value: float = 0.0) -> tuple[int, float] | None:
        self._count += 1
        self._worst = max(self._worst, value)
        if self._said is not None and now - self._said < self.period:
            return None
        said = self._count, self._worst
        self._said, self._count, self._worst = now, 0, -math.inf
        return said


class PacedClock:
    """The time of a model run in real time (an emulator's control loop): ``now()`` is the
    time of the period being run, moved only by :meth:`enter`, so everything the model reports
    (uptime, the frames' cycles and counters) agrees with the time it integrated, however late
    the host runs the loop.

    The loop is paced to ``reference`` (a :class:`RealClock`; a :class:`ScaledClock` for
    ``--speed K``): :meth:`wait_seconds` tells how long to wait for a period. A loop that falls
    behind runs its late periods back to back until it has caught up, as long as it is at most
    ``catch_up`` [s] behind; further behind (a host too busy, a suspended process), its time
    slips instead: the model's time stops being the reference's by that much, the frames come
    late but consistent. Each slip is counted (``overruns``, ``slipped`` [s]) and warned of at
    most every :data:`SLIP_WARN_EVERY` s, through ``log`` (``logging.getLogger(name)``)."""

    is_simulated = False

    def __init__(self, reference: Clock, *, catch_up: float = CATCH_UP,
                 name: str = "lowerbase") -> None:
        if not catch_up > 0:
            raise ValueError(f"catch_up must be > 0 s, not {catch_up}")
        self.reference = reference
        self.catch_up = float(catch_up)
        self.name = name
        self._t = reference.now()
        self._offset = 0.0  # reference time - model time: the sum of the slips
        self._warn = WarnLimiter(SLIP_WARN_EVERY)
        self.overruns = 0  #: slips: times the loop fell more than catch_up behind
        self.slipped = 0.0  #: [s] the model's time lost against the reference, in all

    def now(self) -> float:
        return self._t

    def resync(self) -> None:
        """Pace from here: the reference's time now is the model's (a loop's start, after a
        set-up that took its time); not a slip."""
        self._offset = self.reference.now() - self._t

    def behind(self) -> float:
        """How far [s] the model's time is behind the paced reference right now."""
        return self.reference.now() - self._offset - self._t

    def wait_seconds(self, t: float) -> float:
        """The wall seconds until model time ``t`` is due (<= 0: due already)."""
        return real_seconds(self.reference, t + self._offset - self.reference.now())

    def until_due(self, t: float) -> float:
        """:meth:`wait_seconds` for a loop's wait: 0.0 once ``t`` is due, and a wait under
        :data:`DUE_WITHIN` counts as due (at large times a float sum can leave a wait of a
        few ulps that no sleep can serve: a loop would spin on it)."""
        remaining = self.wait_seconds(t)
        return remaining if remaining > DUE_WITHIN else 0.0

    def enter(self, t: float) -> float:
        """Run the period that starts at model time ``t`` (>= now()): the returned seconds
        [s] the time slipped, 0.0 unless the loop was more than ``catch_up`` behind."""
        if t < self._t:
            raise ValueError(f"cannot move a clock backwards ({t} < {self._t})")
        self._t = float(t)
        lag = self.behind()
        if lag <= self.catch_up:
            return 0.0
        self._offset += lag
        self.overruns += 1
        self.slipped += lag
        if self._warn.take(self.reference.now()) is not None:
            logging.getLogger(self.name).warning(
                "%s fell %.3f s behind real time (a busy host); its time slipped: frames come "
                "late, their times and the motion stay consistent (%d slips, %.3f s in all)",
                self.name, lag, self.overruns, self.slipped)
        return lag

    def sleep_until(self, deadline: float) -> None:
        """Wait for ``deadline`` on the reference, then enter it (a loop's own pacing)."""
        if deadline <= self._t:
            return
        self.reference.sleep_until(deadline + self._offset)
        self.enter(deadline)

    def summary(self) -> str:
        """One phrase for a stop line: '' when the loop kept real time."""
        if not self.overruns:
            return ""
        return (f"fell behind real time {self.overruns} times, its time slipped "
                f"{self.slipped:.3f} s in all (a busy host)")
