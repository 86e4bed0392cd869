"""Docking onto the charger and off it: the task machine's dock-in / dock-out actions.

Dock in: step moves (StepControl) from the navigation's end onto the charger pose
(:func:`~lowerbase.tasks.plan.dock_steps`). The moves measure on /odom; odometry that lost
motion (wheel samples dropped by a loaded driver) ends them off the charger. So, once they
end, the localized pose is checked against the charger pose and, when off by more than
``dock_tolerance`` along its heading / ``dock_yaw_tolerance``, a straight move along its
heading and a turn put it back (:func:`~lowerbase.tasks.plan.dock_correction`, at most
``dock_corrections`` times): the "secondary positioning" of the seed's action type 3. Then the
BMS must report the charger within ``dock_timeout``. Dock out: straight back to the approach.
A step list that ended short (StepControl's FAILED: a step still off after its corrections, by
/odom) is no failure of the task when the localization can finish it: dock-in goes on to the
check above, dock-out to the next action once the charger contact is open. So do moves that
have not ended after ``dock_move_timeout`` (they are cancelled): StepControl has no stall
check, and a robot held by a wall (an overshoot on odometry that lost motion) never arrives.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any, Protocol

from lowerbase.navigation.controller import wrap
from lowerbase.navigation.steps import CANCEL, EXCUTE, FAILED, SUCCEEDED, Step, StepResult
from lowerbase.tasks.model import ActionType, Pose, TaskState
from lowerbase.tasks.plan import TaskConfig, dock_correction, dock_steps
from lowerbase.tasks.status import Chassis
from lowerbase.world.places import Places

log = logging.getLogger(__name__)
Twist = tuple[float, float]


#: [m] a dock-in that ended this far from the charger is planned again in full (turn to face it,
#: drive, turn); nearer, only along the heading (no turn beside the wall behind the charger)
FAR = 0.2


class StepMoves(Protocol):
    """What the task machine needs of step control (the docking moves): a
    :class:`~lowerbase.navigation.steps.StepController` in-process, or the /cmd_vel_control
    action client (:class:`lowerbase.tasks.ros_clients.ActionSteps`). ``steps`` is the running
    list (the machine empties it once it read ``result``); ``tick`` returns the twist to command,
    or None when the moves drive themselves."""

    steps: list[Step]

    @property
    def result(self) -> Any: ...  # a StepResult once the list ended, else None

    def goal(self, mode: int, steps: Sequence[Step] = (), use_avoid: bool = False) -> Any: ...

    def tick(self, odom: Sequence[float]) -> Twist | None: ...


def off_charger(pose: Pose, charger: Pose, cfg: TaskConfig) -> str:
    """Why ``pose`` is not on ``charger`` along the docking line (the error along its heading)
    or in heading, beyond the docking tolerances ('' when it is)."""
    along = (charger[0] - pose[0]) * math.cos(pose[2]) + \
        (charger[1] - pose[1]) * math.sin(pose[2])
    turn = abs(wrap(pose[2] - charger[2]))
    if abs(along) <= cfg.dock_tolerance and turn <= cfg.dock_yaw_tolerance:
        return ""
    return f"{along * 100:+.1f} cm along, {math.degrees(turn):.1f} deg off the charger"


class Docking:
    """The dock-in / dock-out moves of the task machine (a mixin of
    :class:`~lowerbase.tasks.machine.TaskMachine`, which provides the attributes below)."""

    places: Places
    config: TaskConfig
    steps: StepMoves
    docked: bool

    def _fail(self, t: Any, why: str) -> None: ...  # TaskMachine's

    def _next(self, t: Any) -> None: ...  # TaskMachine's

    def _start_dock(self, t: Any, ch: Chassis) -> None:
        charger = self.places.charger
        assert charger is not None
        if t.action.kind == ActionType.DOCK_IN:
            if ch.pose is None:
                return self._fail(t, "docking: no localized pose to dock from")
            moves = dock_steps(ch.pose, charger.pose)
        else:
            back = math.hypot(charger.approach[0] - charger.pose[0],
                              charger.approach[1] - charger.pose[1])
            moves = [(1, -back)]
        if not moves:
            if t.action.kind == ActionType.DOCK_OUT:
                self.docked = False
                return self._next(t)
            self.docked, t.contact_wait = True, 0.0
            return None
        self._move(t, moves)
        return None

    def _move(self, t: Any, moves: list[tuple[int, float]]) -> None:
        speeds = {1: self.config.dock_speed, 2: 0.3}
        t.dock_elapsed = 0.0
        refused = self.steps.goal(EXCUTE, [Step(m, d, speeds[m]) for m, d in moves])
        if refused is not None:
            self._fail(t, f"docking: {refused.message}")

    def _run_dock(self, t: Any, ch: Chassis, dt: float) -> Twist | None:
        if t.contact_wait is not None:  # docked: the BMS must see the charger
            if ch.charging:
                self._next(t)
            elif t.contact_wait >= self.config.dock_timeout:
                self._fail(t, f"docked, but no charger contact within "
                           f"{self.config.dock_timeout:g} s: check the charger place")
            elif t.state == TaskState.EXECUTING:
                t.contact_wait += dt
            return None
        if ch.odom is None:
            return (0.0, 0.0)
        twist = self.steps.tick(ch.odom)
        res = self.steps.result
        if t.state == TaskState.EXECUTING:
            t.dock_elapsed += dt
        if res is None and self.steps.steps and t.dock_elapsed >= self.config.dock_move_timeout:
            # moves that never end (odometry that lost motion drives on against a wall, which
            # holds the robot): stop them, the localization decides as for a short list
            self.steps.goal(CANCEL)
            res = StepResult(FAILED, 0, 0.0, f"the moves did not end within "
                             f"{self.config.dock_move_timeout:g} s: stopped")
        if res is None or not self.steps.steps:
            return twist
        self.steps.steps = []
        short = res.result == FAILED and (t.action.kind == ActionType.DOCK_IN or not ch.charging)
        if short:  # a step ended off (> 2 cm / 1 deg) or stalled: the localization decides
            log.info("docking: %s: going on from where the robot stands", res.message)
        if res.result != SUCCEEDED and not short:
            self._fail(t, f"docking: {res.message}")
        elif t.action.kind == ActionType.DOCK_IN:
            self._docked(t, ch)
        else:
            self.docked = False
            self._next(t)
        return twist

    def _docked(self, t: Any, ch: Chassis) -> None:
        """The dock-in moves ended: on the charger by the localization, or correct."""
        charger = self.places.charger
        assert charger is not None
        pose = None if ch.charging else ch.pose
        why = "" if pose is None else off_charger(pose, charger.pose, self.config)
        if pose is not None and why and t.dock_corrections < self.config.dock_corrections:
            t.dock_corrections += 1
            log.info("docking: %s by the localization: moving onto it again (%d of %d)", why,
                     t.dock_corrections, self.config.dock_corrections)
            far = math.hypot(charger.pose[0] - pose[0], charger.pose[1] - pose[1]) > FAR
            moves = (dock_steps if far else dock_correction)(pose, charger.pose)
            if moves:
                return self._move(t, moves)
        self.docked, t.contact_wait = True, 0.0
        return None
