"""Navigation modes (woosh_msgs/NavigationMode.action) as the Navigator applies them.

What each field does (docs/navigation.md has the table):

- ``navigation_mode``: how the robot handles an obstacle that blocks its path (one the local
  costmap marked and the map does not have):

  * 0 FUZZY: avoid at once, replanning with a small clearance from the obstacle (the padded
    footprint's inscribed radius + 0.1 m) and the inflation costs weighted lightly (the path
    hugs the obstacle);
  * 1 PRECISE (default): avoid at once, replanning with the full clearance (the padded
    footprint's circumscribed radius + 0.1 m: the robot could turn in place anywhere beside it);
  * 2 WAIT: never replan around it: stop in front of it and wait (the goal stays ACTIVE) until it
    is gone, then go on;
  * 3 WAIT_THEN_AVOID: stop and wait ``waiting_timeout`` s, then avoid as PRECISE. In mode 3 a
    ``waiting_timeout`` < 0 makes it PRECISE (the issue's "else precise"; the answer says so).
- ``max_speed``: <= 0: the configured default cruise speed; else the cruise speed (capped by
  the chassis' maxLinear).
- ``nav_dir``: 0 the chassis decides (forward; the final approach may back up to 0.3 m),
  1 forward (as 0), 2 backward (the whole path is driven in reverse), 3 follow the path
  (backward when the path's first metre lies behind the robot, else forward).
- ``permitted_passage``: False forbids driving a changed path: the robot waits in front of an
  obstacle as in mode 2 whatever the mode.
- ``id`` (lane id) and ``capacity``: stored and reported back (:attr:`Navigator.mode`); the
  chassis has no lane map to enforce them on.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class Mode(enum.IntEnum):
    FUZZY = 0
    PRECISE = 1
    WAIT = 2
    WAIT_THEN_AVOID = 3


class NavDir(enum.IntEnum):
    AUTO = 0
    FORWARD = 1
    BACKWARD = 2
    FOLLOW_PATH = 3


#: the largest lane id / capacity a uint32 holds
UINT32_MAX = 2**32 - 1


@dataclass(frozen=True)
class NavigationModeGoal:
    """A /navigation_mode goal (woosh_msgs/NavigationModeGoal's fields and defaults)."""

    navigation_mode: int = 1
    waiting_timeout: float = 0.0
    max_speed: float = 0.0
    id: int = 0
    permitted_passage: bool = True
    capacity: int = 0
    nav_dir: int = 0

    def check(self) -> str:
        """'' if the goal can be applied, else why not (one line)."""
        for name in ("navigation_mode", "id", "capacity", "nav_dir"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int):
                return f"{name} must be an integer, got {v!r}"
        if self.navigation_mode not in tuple(Mode):
            return (f"navigation_mode {self.navigation_mode} is not known; 0 fuzzy avoidance, "
                    f"1 precise avoidance, 2 stop and wait, 3 wait then avoid")
        if self.nav_dir not in tuple(NavDir):
            return (f"nav_dir {self.nav_dir} is not known; 0 chassis decides, 1 forward, "
                    f"2 backward, 3 follow the path")
        for name in ("waiting_timeout", "max_speed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                return f"{name} must be a finite number, got {v!r}"
        if not 0 <= self.id <= UINT32_MAX or not 0 <= self.capacity <= UINT32_MAX:
            return f"id and capacity are uint32, got id {self.id}, capacity {self.capacity}"
        if not isinstance(self.permitted_passage, bool):
            return f"permitted_passage must be a bool, got {self.permitted_passage!r}"
        return ""

    @property
    def effective_mode(self) -> Mode:
        """The mode applied: mode 3 with waiting_timeout < 0 is PRECISE."""
        mode = Mode(self.navigation_mode)
        if mode is Mode.WAIT_THEN_AVOID and self.waiting_timeout < 0:
            return Mode.PRECISE
        return mode

    def avoids_after(self, patience: float) -> float:
        """How long the robot waits, blocked, before replanning around (inf: never)."""
        mode = self.effective_mode
        if not self.permitted_passage or mode is Mode.WAIT:
            return math.inf
        if mode is Mode.WAIT_THEN_AVOID:
            return max(self.waiting_timeout, patience)
        return patience

    @property
    def avoids_early(self) -> bool:
        """Replan as soon as the local costmap blocks the path ahead (modes 0 and 1)."""
        return self.permitted_passage and self.effective_mode in (Mode.FUZZY, Mode.PRECISE)

    @property
    def fuzzy(self) -> bool:
        return self.effective_mode is Mode.FUZZY
