"""An ExecTask execute request checked against the map's places and turned into actions.

Every refusal is a :class:`TaskRefused` whose message says what to send instead; it quotes the
request's strings cut short (:func:`~lowerbase.text.clip`: a 1 MB mark_no by its first 64
characters and its length) and its numbers compactly (``1e+300``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from lowerbase.errors import LowerbaseError
from lowerbase.navigation.controller import wrap
from lowerbase.tasks.model import ActionType, Direction, Pose, TaskRequest, TaskType
from lowerbase.text import clip, point
from lowerbase.world.places import Places


class TaskRefused(LowerbaseError):
    """An exec_task request that is refused; the message is the response's ``message``."""


@dataclass(frozen=True)
class TaskConfig:
    """Tuning of the task machine."""

    load_time: float = 10.0  #: [s] the timed loading action (no lift/roller in the seed)
    unload_time: float = 10.0  #: [s] the timed unloading action
    pose_tolerance: float = 0.01  #: [m] the last pose vs the mark_no's pose
    yaw_tolerance: float = 0.01  #: [rad] the same for the heading
    dock_speed: float = 0.1  #: [m/s] the final approach onto the charger (and back out)
    dock_timeout: float = 10.0  #: [s] after docking, for the BMS to report the charger
    dock_tolerance: float = 0.025  #: [m] docked this near the charger pose (localization)
    dock_yaw_tolerance: float = math.radians(2.0)  #: [rad] and this near its heading
    dock_corrections: int = 2  #: dock-in moves planned again from an off-charger pose
    dock_move_timeout: float = 40.0  #: [s] docking moves still running then are stopped
    full_soc: float = 100.0  #: [%] a charging task undocks and completes at this charge
    auto_charge: bool = True  #: go and charge on a low battery once no task runs
    period: float = 0.05  #: [s] tick period (20 Hz, as a navigation stack)
    #: [s] the path must be blocked this long in a row before the action warns (0: at once)
    blocked_delay: float = 0.5

    def __post_init__(self) -> None:
        for name in ("load_time", "unload_time", "pose_tolerance", "yaw_tolerance",
                     "dock_speed", "dock_timeout", "dock_tolerance", "dock_yaw_tolerance",
                     "dock_move_timeout", "period"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise LowerbaseError(f"task config {name} must be a number > 0, got {value!r}")
        if not (math.isfinite(self.blocked_delay) and self.blocked_delay >= 0):
            raise LowerbaseError(f"task config blocked_delay must be a number >= 0, "
                                 f"got {self.blocked_delay!r}")
        if not (isinstance(self.dock_corrections, int) and self.dock_corrections >= 0):
            raise LowerbaseError(f"task config dock_corrections must be an integer >= 0, "
                                 f"got {self.dock_corrections!r}")
        if not 0 < self.full_soc <= 100:
            raise LowerbaseError(f"task config full_soc must be within (0, 100], "
                                 f"got {self.full_soc!r}")


@dataclass(frozen=True)
class Action:
    """One step of a task: navigate to ``target`` (along ``poses``), dock in or out, load or
    unload for ``duration`` s, or charge."""

    kind: ActionType
    target: Pose | None = None
    poses: tuple[Pose, ...] = ()
    duration: float = 0.0


def _finite(pose: Pose) -> bool:
    return len(pose) == 3 and all(math.isfinite(v) for v in pose)


def _same(a: Pose, b: Pose, cfg: TaskConfig) -> bool:
    return math.hypot(a[0] - b[0], a[1] - b[1]) <= cfg.pose_tolerance and \
        abs(wrap(a[2] - b[2])) <= cfg.yaw_tolerance


def _fmt(p: Pose) -> str:
    return point(*p, decimals=3)


def target_of(req: TaskRequest, places: Places, cfg: TaskConfig) -> tuple[Pose, str]:
    """The navigation target of an execute request and its name (``dest``)."""
    for i, p in enumerate(req.poses, 1):
        if not _finite(p):
            raise TaskRefused(f"pose {i} is not a finite (x, y, yaw): send finite poses")
    if req.task_type == TaskType.CHARGING:
        if places.charger is None:
            raise TaskRefused("this map has no charger: add one to its places file "
                              "(charger: pose, approach)")
        if req.mark_no not in ("", "charger"):
            raise TaskRefused(f"a charging task goes to the charger: leave mark_no empty or "
                              f"send 'charger', not {clip(req.mark_no)}")
        mark, name = places.charger.approach, "charger"
    elif req.mark_no:
        named = places.named()
        if req.mark_no not in named:
            some = ", ".join(sorted(places.storage)[:3]) or "none"
            raise TaskRefused(f"unknown mark_no {clip(req.mark_no)}: this map has "
                              f"{len(places.storage)} storage points (e.g. {some})")
        mark, name = named[req.mark_no], req.mark_no
    elif req.poses:
        return req.poses[-1], _fmt(req.poses[-1])
    else:
        raise TaskRefused("no target: send a mark_no (a storage point) or poses")
    if req.poses and not _same(req.poses[-1], mark, cfg):
        raise TaskRefused(f"the last pose {_fmt(req.poses[-1])} is not {name} at {_fmt(mark)}: "
                          f"end the poses there or leave them empty")
    return mark, name


def plan(req: TaskRequest, places: Places, cfg: TaskConfig) -> tuple[list[Action], str]:
    """The actions of an execute request and its ``dest`` (TaskRefused if it cannot run)."""
    if req.task_id <= 0:
        raise TaskRefused(f"task_id must be > 0 (0 is the robot's own charging), "
                          f"got {req.task_id}")
    if req.task_type not in (1, 2, 3, 4):
        raise TaskRefused(f"unknown task_type {req.task_type}: 1 picking, 2 parking, "
                          "3 charging, 4 transporting")
    if req.direction not in (0, 1, 2):
        raise TaskRefused(f"unknown direction {req.direction}: 0 none, 1 load, 2 unload")
    if req.direction and req.task_type in (TaskType.PARKING, TaskType.CHARGING):
        raise TaskRefused(f"a {TaskType(req.task_type).name.lower()} task has no load/unload: "
                          "send direction 0")
    target, dest = target_of(req, places, cfg)
    actions = [Action(ActionType.NAVIGATION, target, tuple(req.poses))]
    if req.task_type == TaskType.CHARGING:
        actions += [Action(ActionType.DOCK_IN), Action(ActionType.CHARGING),
                    Action(ActionType.DOCK_OUT)]
    elif req.direction == Direction.LOAD:
        actions.append(Action(ActionType.TRANSPORT, duration=cfg.load_time))
    elif req.direction == Direction.UNLOAD:
        actions.append(Action(ActionType.TRANSPORT, duration=cfg.unload_time))
    return actions, dest


def dock_steps(pose: Pose, charger: Pose) -> list[tuple[int, float]]:
    """The final approach from ``pose`` onto the ``charger`` pose as step moves
    ``(executeMode, data)``: turn to face it, drive straight onto it, turn to its heading
    (turns below 0.5 deg and drives below 5 mm left out)."""
    from lowerbase.navigation.steps import ROTATE, STRAIGHT

    dx, dy = charger[0] - pose[0], charger[1] - pose[1]
    dist = math.hypot(dx, dy)
    steps: list[tuple[int, float]] = []
    heading = pose[2]
    if dist >= 0.005:
        bearing = math.atan2(dy, dx)
        turn = wrap(bearing - pose[2])
        if abs(turn) >= math.radians(0.5):
            steps.append((ROTATE, turn))
        steps.append((STRAIGHT, dist))
        heading = bearing
    turn = wrap(charger[2] - heading)
    if abs(turn) >= math.radians(0.5):
        steps.append((ROTATE, turn))
    return steps


def dock_correction(pose: Pose, charger: Pose) -> list[tuple[int, float]]:
    """Step moves that put ``pose`` back on the ``charger`` pose along the docking line: straight
    (forwards or back) by the error along the robot's heading, then a turn to the charger's
    heading. No turning towards the charger: beside it a turn can sweep the footprint into the
    wall behind the charger. The error across the heading stays (it is the approach's)."""
    from lowerbase.navigation.steps import ROTATE, STRAIGHT

    along = (charger[0] - pose[0]) * math.cos(pose[2]) + \
        (charger[1] - pose[1]) * math.sin(pose[2])
    steps: list[tuple[int, float]] = []
    if abs(along) >= 0.005:
        steps.append((STRAIGHT, along))
    turn = wrap(charger[2] - pose[2])
    if abs(turn) >= math.radians(0.5):
        steps.append((ROTATE, turn))
    return steps
