"""The campaign's progress line on stderr: done / failed / running and the time left."""

from __future__ import annotations

import sys
import time
from typing import TextIO


def _clock(seconds: float) -> str:
    s = round(seconds)
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


class CampaignProgress:
    """``[#####.....] 42/100  done 40  failed 2  running 2  2:31 elapsed, ~3:28 left``;
    redrawn in place on a terminal (or with ``force``), silent otherwise."""

    WIDTH = 30

    def __init__(self, total: int, *, force: bool = False, stream: TextIO | None = None
                 ) -> None:
        self.total = total
        self.stream = stream or sys.stderr
        self.enabled = force or self.stream.isatty()
        self.t0 = time.monotonic()
        self.done = self.failed = self.running = 0
        self._last = 0.0

    def line(self, now: float | None = None) -> str:
        elapsed = (now if now is not None else time.monotonic()) - self.t0
        finished = self.done + self.failed
        filled = self.WIDTH * finished // max(self.total, 1)
        left = "?" if not finished else _clock(elapsed / finished * (self.total - finished))
        return (f"[{'#' * filled}{'.' * (self.WIDTH - filled)}] {finished}/{self.total}  "
                f"done {self.done}  failed {self.failed}  running {self.running}  "
                f"{_clock(elapsed)} elapsed, ~{left} left")

    def update(self, *, done: int, failed: int, running: int, force: bool = False) -> None:
        self.done, self.failed, self.running = done, failed, running
        now = time.monotonic()
        if self.enabled and (force or now - self._last >= 0.1):
            self._last = now
            self.stream.write("\r" + self.line(now) + "\x1b[K")
            self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\r" + self.line() + "\x1b[K\n")
            self.stream.flush()
