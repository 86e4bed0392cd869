"""When navigation's "path blocked" becomes the task's warning: :class:`BlockedDebounce`.

The navigator reports BLOCKED on every tick its collision check fails, and waits or replans
on its own (its ``blocked_patience``). One such tick is not yet worth a warning: an obstacle at
the edge of the check's margin, or a costmap cell that flickers between scans, would flip
robot_status WARNING/task every period. As move_base users expect, the task warns only once the
path has been blocked continuously for ``delay`` s (on the machine's clock) and stops warning
on the first tick it is free. The machine (and so TaskSim and the ROS node) asks this one place.
"""

from __future__ import annotations

from typing import Any


def blocked(status: Any, reason: str) -> bool:
    """Whether navigation's feedback (its status and reason) says the path is blocked."""
    return "block" in f"{status} {reason}".lower()


class BlockedDebounce:
    """Reports blocked only after ``delay`` s of blocked ticks in a row (0: at once)."""

    def __init__(self, delay: float) -> None:
        self.delay = delay
        self.since: float | None = None  #: the first tick of the current blocked run

    def reset(self) -> None:
        """Forget the current run (a goal was sent: the wait starts again)."""
        self.since = None

    def update(self, is_blocked: bool, now: float) -> bool:
        """One navigation tick: whether the block is to be reported now."""
        if not is_blocked:
            self.since = None
            return False
        if self.since is None:
            self.since = now
        return now - self.since + 1e-9 >= self.delay
