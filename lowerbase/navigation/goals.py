"""The Navigator's goal bookkeeping: its parameters (:class:`NavigatorConfig`), the goal states
(actionlib's), one control step's answer (:class:`NavCommand`), ended goals
(:class:`GoalResult`), and the plan checks it replans by: :func:`path_blocked` (the rest of the
plan crosses an INSCRIBED or LETHAL cell) and :func:`unblocked_start` (a start inside inflation
is planned out of)."""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lowerbase.errors import WorldError
from lowerbase.navigation.controller import ControllerConfig, Status, wrap
from lowerbase.navigation.costmap import CostmapParams
from lowerbase.navigation.layers import InflationParams
from lowerbase.navigation.planner import INSCRIBED, GlobalPlanner
from lowerbase.navigation.recovery import ORDER, BackOffConfig, check_behaviors
from lowerbase.text import num, point

Pose = tuple[float, float, float]


class NavigationError(WorldError):
    """A navigation request that cannot be taken: a NaN or off-map goal."""


class GoalState(enum.Enum):
    """actionlib's goal states; SUCCEEDED, ABORTED and PREEMPTED are final."""

    PENDING = "pending"
    ACTIVE = "active"
    SUCCEEDED = "succeeded"
    ABORTED = "aborted"
    PREEMPTED = "preempted"

    @property
    def terminal(self) -> bool:
        return self in (GoalState.SUCCEEDED, GoalState.ABORTED, GoalState.PREEMPTED)


def _inflation() -> CostmapParams:
    return CostmapParams(inflation=InflationParams(inflation_radius=1.0, cost_scaling_factor=3.0))


@dataclass(frozen=True)
class NavigatorConfig:
    """move_base's parameters for the Navigator (times in s, distances in m, angles in rad)."""

    xy_tolerance: float = 0.05
    yaw_tolerance: float = math.radians(2.0)
    blocked_patience: float = 1.0  #: BLOCKED this long before replanning (modes 0, 1)
    max_replans: int = 5  #: replans while blocked per goal before ABORTED
    max_early_replans: int = 20  #: replans as new obstacles come into view, per goal
    stuck_timeout: float = 10.0  #: no progress this long (not waiting): ABORTED
    #: the newest scan or localization older than this: stop and wait for them (not blind)
    sensing_timeout: float = 0.5
    sensing_patience: float = 10.0  #: out of date this long: ABORTED
    progress_distance: float = 0.05  #: moving this far counts as progress
    progress_angle: float = math.radians(5.0)  #: turning this far counts as progress
    default_max_speed: float = 0.6  #: cruise speed when the mode's max_speed <= 0
    goal_tolerance: float = 0.0  #: the planner's tolerance for goals (GetPlan's)
    replan_interval: float = 0.5  #: at most one early replan (path ahead blocked) per this
    costmap: CostmapParams = field(default_factory=_inflation)  #: global costmap
    local_size: float = 5.0  #: local rolling window, square [m]
    cost_scale: float = 15.0  #: planner: a cell of cost c is 1 + c/cost_scale long
    fuzzy_cost_scale: float = 1000.0  #: the same in mode 0 (inflation weighs little)
    clearance_margin: float = 0.1  #: keep-out beyond the footprint's radius (modes 0, 1)
    #: planner: cells of at least the circumscribed cost (the footprint fits there only at
    #: some headings) are this many times as long, except in mode 0 (fuzzy)
    narrow_penalty: float = 10.0
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    back_off: BackOffConfig = field(default_factory=BackOffConfig)  #: before each replan
    #: move_base's recovery_behaviors: what runs before the 2nd, 3rd, ... blocked replan
    #: (names of ``recovery.BEHAVIORS``; the last one repeats)
    recovery_behaviors: tuple[str, ...] = ORDER
    #: no plan while the local costmap holds marks: reset its obstacle layer, plan again
    clear_on_no_path: bool = True

    def __post_init__(self) -> None:
        for name in ("xy_tolerance", "yaw_tolerance", "blocked_patience", "stuck_timeout",
                     "sensing_timeout", "sensing_patience",
                     "progress_distance", "progress_angle", "default_max_speed",
                     "goal_tolerance", "replan_interval", "local_size", "cost_scale",
                     "fuzzy_cost_scale", "clearance_margin"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise NavigationError(f"navigator {name} = {v!r} is invalid; allowed: >= 0")
        if not (isinstance(self.narrow_penalty, (int, float))
                and math.isfinite(self.narrow_penalty) and self.narrow_penalty >= 1):
            raise NavigationError(f"navigator narrow_penalty = {self.narrow_penalty!r} is "
                                  f"invalid; allowed: >= 1")
        why = check_behaviors(self.recovery_behaviors)
        if why:
            raise NavigationError(f"navigator recovery_behaviors: {why}")
        for name in ("max_replans", "max_early_replans"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 0:
                raise NavigationError(f"navigator {name} = {v!r} is invalid; allowed: an "
                                      f"integer >= 0")


@dataclass(frozen=True)
class NavCommand:
    """One control step: the twist to send (/base_cmd_vel), the goal's state, the controller's
    status and why (the reason of a final state, or what the robot waits for)."""

    linear: float
    angular: float
    state: GoalState
    status: Status
    reason: str = ""


@dataclass(frozen=True)
class GoalResult:
    """A goal that ended: its id (1, 2, ... in sending order), final state, reason, time."""

    goal_id: int
    state: GoalState
    reason: str
    stamp: float


def _pose(value: Sequence[float], what: str) -> Pose:
    try:
        x, y, yaw = (float(v) for v in value)
    except (TypeError, ValueError):
        raise NavigationError(f"the {what} is (x, y, yaw) numbers, got {value!r}") from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise NavigationError(f"the {what} must be finite numbers, got ({x}, {y}, {yaw})")
    return x, y, yaw


def off_map(extent: Sequence[float], x: float, y: float) -> float:
    """How far [m] the point (x, y) lies outside the map's ``extent`` (x_min, y_min, x_max,
    y_max); 0 on it (the far edges count as off, as the cells there do not exist); NaN: inf."""
    x0, y0, x1, y1 = extent
    if x0 <= x < x1 and y0 <= y < y1:
        return 0.0
    if not (math.isfinite(x) and math.isfinite(y)):
        return math.inf
    return max(math.hypot(max(x0 - x, 0.0, x - x1), max(y0 - y, 0.0, y - y1)), 1e-12)


def check_on_map(extent: Sequence[float], x: float, y: float, what: str,
                 tolerance: float = 0.0) -> None:
    """:class:`NavigationError` when (x, y) lies off the map by more than ``tolerance`` [m];
    the numbers are written compactly (a 1e300 is ``1e+300``, not 301 digits)."""
    if off_map(extent, x, y) > tolerance:
        x0, y0, x1, y1 = extent
        within = f" by more than the tolerance {num(tolerance)} m" if tolerance > 0 else ""
        raise NavigationError(f"the {what} {point(x, y)} is off the map (x {num(x0)}..{num(x1)}"
                              f" m, y {num(y0)}..{num(y1)} m){within}: give a pose on the map")


def path_blocked(rest: Sequence[Pose] | np.ndarray, costs: np.ndarray, resolution: float,
                 origin: Sequence[float]) -> bool:
    """Whether any of the poses ``rest`` lies on an INSCRIBED or LETHAL cell of ``costs``."""
    if not len(rest):
        return False
    pts = np.asarray(rest)
    rows = np.floor((pts[:, 1] - origin[1]) / resolution).astype(int)
    cols = np.floor((pts[:, 0] - origin[0]) / resolution).astype(int)
    ok = (rows >= 0) & (cols >= 0) & (rows < costs.shape[0]) & (cols < costs.shape[1])
    return bool((costs[rows[ok], cols[ok]] >= INSCRIBED).any())


def unblocked_start(planner: GlobalPlanner, start: Pose, inscribed_radius: float
                    ) -> GlobalPlanner:
    """A planner whose costs let the robot out of the inflation it stands in (not out of
    LETHAL cells: cells within the inscribed radius of the start are lowered to 252)."""
    costs = np.array(planner.costs)
    res = planner.resolution
    rad = inscribed_radius
    r0, c0 = planner.cell(start[0], start[1])
    n = math.ceil(rad / res)
    rr, cc = np.mgrid[r0 - n:r0 + n + 1, c0 - n:c0 + n + 1]
    keep = (np.hypot(rr - r0, cc - c0) * res <= rad) & (rr >= 0) & (cc >= 0) \
        & (rr < costs.shape[0]) & (cc < costs.shape[1])
    rr, cc = rr[keep], cc[keep]
    sel = costs[rr, cc] == INSCRIBED
    costs[rr[sel], cc[sel]] = 252
    out = GlobalPlanner(costs, res, planner.origin, cost_scale=planner.cost_scale,
                        narrow_cost=planner.narrow_cost, narrow_penalty=planner.narrow_penalty)
    out.footprint = planner.footprint
    return out


class _SegmentLengths:
    """The last path's segment lengths, computed once per path: :func:`remaining` runs every
    control period and the plan changes only when replanned. A path is the same if it is the
    same object with the same length and ends (the Navigator replaces its plan, never edits it
    in place); anything else is computed afresh."""

    def __init__(self) -> None:
        self._path: Sequence[Pose] | None = None
        self._key: tuple[int, tuple[float, ...], tuple[float, ...]] | None = None
        self._seg = np.zeros(0)

    def of(self, path: Sequence[Pose]) -> np.ndarray:
        key = (len(path), tuple(path[0]), tuple(path[-1]))
        if path is not self._path or key != self._key:
            xy = np.asarray(path)[:, :2]
            self._path, self._key = path, key
            self._seg = np.hypot(*np.diff(xy, axis=0).T)
        return self._seg


_SEGMENTS = _SegmentLengths()


def remaining(path: Sequence[Pose], index: int, p: Pose, approach_distance: float) -> float:
    """The distance left along ``path`` from ``p`` (its pose ``index`` on); straight to the
    goal within ``approach_distance`` of it (the final approach goes straight at it). The
    segment lengths are the path's, computed once (:class:`_SegmentLengths`); their sum from
    ``index`` on is the same numpy sum of the same values as over the sliced path's own
    segments, bit for bit (tests/navigation/test_remaining.py)."""
    if not path:
        return 0.0
    gx, gy, _ = path[-1]
    straight = math.hypot(gx - p[0], gy - p[1])
    if index >= len(path) or straight <= approach_distance:
        return straight
    seg = _SEGMENTS.of(path)[index:]
    along = float(seg.sum()) if seg.size else 0.0
    x0, y0 = float(path[index][0]), float(path[index][1])
    return math.hypot(x0 - p[0], y0 - p[1]) + along


class ProgressWatch:
    """move_base's oscillation / progress check: a goal is stuck when the robot has not moved
    ``distance`` [m] or turned ``angle`` [rad] from the last reference pose for ``timeout`` s.
    Waiting for an obstacle, recovering and replanning restart it (:meth:`restart`)."""

    def __init__(self, distance: float, angle: float, timeout: float) -> None:
        self.distance, self.angle, self.timeout = distance, angle, timeout
        self.ref: tuple[float, Pose] | None = None

    def restart(self, now: float, pose: Pose) -> None:
        self.ref = (now, pose)

    def stuck(self, now: float, pose: Pose) -> str:
        """'' while progressing (a move from the reference restarts it), else why stuck."""
        if self.ref is None:
            self.restart(now, pose)
            return ""
        t0, q = self.ref
        if math.hypot(pose[0] - q[0], pose[1] - q[1]) >= self.distance or \
                abs(wrap(pose[2] - q[2])) >= self.angle:
            self.restart(now, pose)
            return ""
        if now - t0 >= self.timeout:
            return f"stuck: no progress for {self.timeout:g} s"
        return ""
