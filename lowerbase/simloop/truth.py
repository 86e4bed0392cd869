"""The emulator's ground truth, read out as it runs.

* :class:`TruthHook`: an ``on_step`` hook of the MCU runner that samples the truth on a grid.
* :class:`TruthLog`: the ground truth as CSV (``lowerbase emulate --truth FILE``), so a run
  over processes can still plot where the robot really was.
* :class:`TruthFollower`: reads a growing :class:`TruthLog` from another process.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, TextIO

from lowerbase.errors import ConfigError


class TruthHook:
    """``on_step`` hook of the MCU runner that hands the ground truth to :meth:`emit` once
    every ``period`` [s] of emulator time on average, with ``t`` [s] since the first boot.

    Samples are due on a grid of ``period`` from the first one, so a step that comes a little
    late (a real-time loop's latency, K times longer on ``emulate --speed K``) does not push
    every later sample back; a sample more than a period late restarts the grid (no burst)."""

    def __init__(self, period: float) -> None:
        self.period = period
        self._t0: float | None = None
        self._next = -math.inf

    def __call__(self, mcu: Any) -> None:
        now = mcu.clock.now()
        if self._t0 is None:
            self._t0 = mcu.boot_time
        if now < self._next - 1e-9:
            return
        due = self._next + self.period
        self._next = due if due > now else now + self.period
        self.emit(mcu, now - self._t0)

    def emit(self, mcu: Any, t: float) -> None:
        raise NotImplementedError


class TruthLog(TruthHook):
    """``on_step`` hook of the MCU runner: the ground truth as CSV every ``period`` [s].

    Columns ``t,x,y,yaw,v,w``: t [s] since the first boot, pose [m, m, rad], twist [m/s,
    rad/s]. Lines are flushed as written, so another process can follow the file.
    """

    HEADER = "t,x,y,yaw,v,w\n"

    def __init__(self, path: str | Path, period: float = 0.02) -> None:
        super().__init__(period)
        self.path = Path(path)
        try:
            self._file: TextIO = self.path.open("w", encoding="utf-8", buffering=1)
        except OSError as exc:
            raise ConfigError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._file.write(self.HEADER)

    def emit(self, mcu: Any, t: float) -> None:
        tr = mcu.truth
        self._file.write(f"{t:.4f},{tr.x:.6f},{tr.y:.6f},{tr.yaw:.6f},"
                         f"{tr.v:.5f},{tr.w:.5f}\n")

    def close(self) -> None:
        self._file.close()


class TruthFollower:
    """Reads a growing :class:`TruthLog` file; ``latest()`` is the newest complete row."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._file: TextIO | None = None
        self._partial = ""
        self.row: tuple[float, float, float, float, float, float] | None = None

    def latest(self) -> tuple[float, float, float, float, float, float] | None:
        if self._file is None:
            try:
                self._file = self.path.open("r", encoding="utf-8")
            except OSError:
                return None
        chunk = self._file.read()
        if chunk:
            lines = (self._partial + chunk).split("\n")
            self._partial = lines.pop()
            for line in reversed(lines):
                parts = line.split(",")
                if len(parts) == 6 and parts[0] != "t":
                    try:
                        self.row = tuple(float(p) for p in parts)  # type: ignore[assignment]
                    except ValueError:
                        continue
                    break
        return self.row

    def close(self) -> None:
        if self._file is not None:
            self._file.close()

