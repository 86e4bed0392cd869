"""How well the host kept a real-time scenario run on its schedule.

A run on the wall clock ("realtime", "processes") cannot be faster than its host: a step that
starts late, or a lower computer that falls behind (its Heartbeat's Overruns), shifts what
happens against the scenario's times. The run counts it here, and the verdict says so next to
the expectations, so a timing expectation that failed on a busy host is not mistaken for (or
hidden as) a defect of the robot. On the simulated clock nothing is ever late.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

#: [s] a step that starts this much or more after its due time is counted late
LATE_STEP = 0.05


@dataclass
class HostLag:
    late_steps: int = 0  #: steps that started LATE_STEP or more after their due time
    max_late: float = 0.0  #: [s] the latest of them
    lower_overruns: int = 0  #: the lower computer's own count of falling behind real time

    def step_started(self, late: float) -> None:
        """A step began ``late`` [s] after its due time."""
        if late >= LATE_STEP:
            self.late_steps += 1
            self.max_late = max(self.max_late, late)

    @property
    def lagged(self) -> bool:
        return self.late_steps > 0 or self.lower_overruns > 0

    def describe(self) -> str:
        """One line: what the host did to the run's timing ('' when nothing)."""
        parts = []
        if self.late_steps:
            parts.append(f"{self.late_steps} step{'s' if self.late_steps != 1 else ''} "
                         f"started late (worst {self.max_late:.2f} s)")
        if self.lower_overruns:
            parts.append(f"the lower computer counted {self.lower_overruns} Overruns")
        if not parts:
            return ""
        return (f"the host fell behind real time: {', '.join(parts)}; a timing expectation "
                "may have failed for that reason (run it again on a quieter host, or without "
                "--processes on the simulated clock)")

    def as_dict(self) -> dict[str, Any]:
        return {"late_steps": self.late_steps, "max_late_s": round(self.max_late, 4),
                "lower_overruns": self.lower_overruns, "lagged": self.lagged}
