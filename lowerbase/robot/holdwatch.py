"""A lockstep robot whose simulated time stops although it should run: :class:`HoldWatch`.

In lockstep every publication is written on the loop's thread (nothing is dropped), so an
outside subscriber that reads no more (a stopped process, a debugger at a breakpoint) holds
simulated time once its socket is full. That is by design (the robot waits for its slowest
reader); what must not be is silence. The watch, a thread of its own, looks every
``period`` wall seconds; simulated time held ``warn_after`` wall seconds while it should move
(free-running, or a step running) is warned of, at most once per ``warn_every`` s, with who
holds it (``holders``, e.g. :func:`lowerbase.ros1.held.backlogs`: topic -> subscriber, unsent
bytes). Ctrl-C stops a held robot all the same (the signal interrupts the blocked write).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from lowerbase.clock import WarnLimiter

WARN_AFTER = 5.0  #: [s of wall time] simulated time held this long is warned of
WARN_EVERY = 30.0  #: [s of wall time] between two such warnings
PERIOD = 0.5  #: [s of wall time] between two looks

log = logging.getLogger("lowerbase.robot")


class HoldWatch:
    """See the module docstring. :meth:`look` is one look (pure but for the log);
    :meth:`start` runs it every ``period`` s in a daemon thread."""

    def __init__(self, now: Callable[[], float], should_run: Callable[[], bool],
                 holders: Callable[[], Sequence[Any]], *, warn_after: float = WARN_AFTER,
                 warn_every: float = WARN_EVERY, period: float = PERIOD,
                 wall: Callable[[], float] = time.monotonic) -> None:
        self.now, self.should_run, self.holders = now, should_run, holders
        self.warn_after, self.period = warn_after, period
        self.wall = wall
        self._warn = WarnLimiter(warn_every)
        self._sim: float | None = None
        self._since = 0.0
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        self.stats = {"holds_warned": 0}

    def look(self) -> str | None:
        """One look: the warning said now, if any."""
        t, sim = self.wall(), self.now()
        if sim != self._sim or not self.should_run():
            self._sim, self._since = sim, t
            return None
        held = t - self._since
        if held < self.warn_after:
            return None
        said = self._warn.take(t, held)
        if said is None:
            return None
        self.stats["holds_warned"] += 1
        holders = list(self.holders())
        who = (f"subscribers that read no more hold it (a stopped process, a debugger): "
               f"{', '.join(map(str, holders[:3]))}; it goes on when they read again "
               "(docs/robot.md)" if holders else
               "no subscriber holds it: one step of the robot takes this long (a busy host?)")
        text = f"simulated time held at {sim:.3f} s for {held:.0f} s of wall time: {who}"
        log.warning(text)
        return text

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="lowerbase-hold-watch",
                                        daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._done.wait(self.period):
            try:
                self.look()
            except Exception as exc:  # a watch must not take the robot down
                log.warning("the hold watch stopped looking (the robot goes on): %s: %s",
                            type(exc).__name__, exc)
                return

    def close(self) -> None:
        self._done.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
