"""The task state machine behind exec_task and robot_status (ROS-free, on any clock).

:meth:`TaskMachine.request` answers an ExecTask request; :meth:`TaskMachine.tick` (every
``config.period``, 20 Hz) reads the chassis, runs the current action and returns the twist to
command (None: nothing to command). Every change of the status goes through a
:class:`~lowerbase.tasks.status.StatusTracker` (robot_status, only on change). docs/tasks.md
has the whole table: transitions, what faults do, which requests are refused when.

The machine is three parts: this module (the actions' life cycle and the tick: chassis events,
navigation, timed actions, charging), :mod:`~lowerbase.tasks.requests` (exec_task requests) and
:mod:`~lowerbase.tasks.docking` (dock in / out); :mod:`~lowerbase.tasks.task` holds the
:class:`Task` and the :class:`Navigation` it drives (importable from here as before).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

from lowerbase.errors import LowerbaseError
from lowerbase.navigation.steps import CANCEL, PAUSE, RESUM, StepController
from lowerbase.tasks.blocked import BlockedDebounce, blocked
from lowerbase.tasks.docking import Docking, StepMoves
from lowerbase.tasks.model import (
    AUTO_TASK_ID,
    ActionState,
    ActionType,
    Pose,
    RobotState,
    Status,
    TaskExect,
    TaskRequest,
    TaskState,
    TaskType,
)
from lowerbase.tasks.plan import TaskConfig, TaskRefused
from lowerbase.tasks.requests import Requests
from lowerbase.tasks.status import Chassis, StatusTracker, robot_state
from lowerbase.tasks.task import ESTOP_MSG, NavFeedback, Navigation, Task, Twist, pct
from lowerbase.world.places import Places

__all__ = ["ESTOP_MSG", "NavFeedback", "Navigation", "Task", "TaskMachine", "Twist"]

log = logging.getLogger(__name__)


class TaskMachine(Requests, Docking):
    def __init__(self, nav: Navigation, places: Places, config: TaskConfig | None = None, *,
                 on_status: Callable[[Status], None] | None = None,
                 steps: StepMoves | None = None) -> None:
        self.nav = nav
        self.places = places
        self.config = config or TaskConfig()
        self.steps: StepMoves = steps if steps is not None else StepController(
            period=self.config.period, settle=0.2)
        self.task: Task | None = None
        self.chassis = Chassis(initialized=False)
        self.docked = False  #: on the charger (a dock-in finished, no dock-out since)
        self.tracker = StatusTracker(on_status)
        self.blocked = BlockedDebounce(self.config.blocked_delay)  #: path-blocked warning
        self.now = 0.0
        self._last_tick: float | None = None
        self._auto_tried = False
        self._wait_ids = 0
        self._refresh()

    # -- views ----------------------------------------------------------------------------------
    @property
    def active(self) -> bool:
        return self.task is not None and self.task.active

    def robot_state(self) -> RobotState:
        t = self.task if self.active else None
        return robot_state(self.chassis, t.request.task_type if t else None,
                           t is not None and t.action_state == ActionState.WARNING)

    def status(self) -> Status:
        ch, t, rs = self.chassis, self.task, self.robot_state()
        note = ch.abnormal()
        if not note and ch.critical_battery:
            note = f"battery critical{pct(ch.soc)}"
        elif not note and ch.low_battery:
            note = f"battery low{pct(ch.soc)}"
        elif not note and not ch.localized:
            note = "localization lost"
        elif not note and ch.uncertain:
            note = f"localization {ch.uncertain}"
        if t is None:
            return Status(robot_state=rs, msg=note)
        kind = ActionType.WAITING if t.state == TaskState.WAITING else t.action.kind
        return Status(task_id=t.request.task_id, task_type=t.request.task_type,
                      task_state=t.state, action_type=kind, action_state=t.action_state,
                      robot_state=rs, wait_id=t.wait_id, dest=t.dest, msg=t.msg or note)

    def _refresh(self) -> None:
        self.tracker.update(self.status(), self.now)

    # -- actions --------------------------------------------------------------------------------
    def _start(self, t: Task) -> None:
        a, ch = t.action, self.chassis
        t.action_state, t.elapsed, t.contact_wait, t.lost = ActionState.EXECUTING, 0.0, None, \
            False
        if a.kind == ActionType.NAVIGATION:
            assert a.target is not None
            if ch.localized and ch.pose is not None:
                self._send(t, a.target, a.poses)
            else:
                self._lose(t)
        elif a.kind in (ActionType.DOCK_IN, ActionType.DOCK_OUT):
            self._start_dock(t, ch)
        return None

    def _send(self, t: Task, target: Pose, poses: Sequence[Pose]) -> None:
        self.blocked.reset()
        try:
            self.nav.send_goal(target, poses, now=self.now)
        except LowerbaseError as exc:  # an off-map pose
            self._fail(t, f"navigation refused the goal: {exc}")

    def _next(self, t: Task) -> None:
        t.index += 1
        if t.index >= len(t.actions):
            t.index = len(t.actions) - 1
            t.state, t.action_state, t.msg = TaskState.COMPLETED, ActionState.COMPLETED, "done"
            log.info("task %d completed", t.request.task_id)
            return
        self._start(t)

    def _fail(self, t: Task, why: str) -> None:
        self._stop(t, TaskState.FAILED, ActionState.FAILED, why)
        log.warning("task %d failed: %s", t.request.task_id, why)

    def _stop(self, t: Task, state: TaskState, action_state: ActionState, msg: str) -> None:
        if t.action.kind == ActionType.NAVIGATION:
            self.nav.cancel(self.now)
        elif t.action.kind in (ActionType.DOCK_IN, ActionType.DOCK_OUT):
            self.steps.goal(CANCEL)
        t.state, t.action_state, t.msg = state, action_state, msg

    def _halt(self, t: Task, state: TaskState, msg: str) -> None:
        if t.action.kind == ActionType.NAVIGATION and not t.lost:
            self.nav.cancel(self.now)
        elif t.action.kind in (ActionType.DOCK_IN, ActionType.DOCK_OUT):
            self.steps.goal(PAUSE)
        t.state, t.action_state, t.msg = state, ActionState.PAUSED, msg

    def _resume(self, t: Task) -> None:
        t.state, t.action_state, t.msg = TaskState.EXECUTING, ActionState.EXECUTING, ""
        if t.action.kind == ActionType.NAVIGATION:
            ch = self.chassis
            if ch.localized and ch.pose is not None:
                t.lost = False
                assert t.action.target is not None
                self._send(t, t.action.target, t.action.poses)
            else:
                self._lose(t)
        elif t.action.kind in (ActionType.DOCK_IN, ActionType.DOCK_OUT):
            self.steps.goal(RESUM)

    def _lose(self, t: Task) -> None:
        if not t.lost and t.action.kind == ActionType.NAVIGATION:
            t.lost = True
            t.action_state, t.msg = ActionState.WARNING, \
                "localization lost: navigation waits for it to return"

    # -- ticking --------------------------------------------------------------------------------
    def tick(self, now: float, chassis: Chassis) -> Twist | None:
        """One period: watch the chassis, run the action; the twist to command or None."""
        dt = 0.0 if self._last_tick is None else max(now - self._last_tick, 0.0)
        self.now, self._last_tick, self.chassis = now, now, chassis
        twist: Twist | None = None
        t = self.task
        if t is not None and t.active:
            self._watch(t, chassis)
        if t is not None and t.active:
            twist = self._run(t, chassis, dt)
        self._refresh()  # a task that ended here is published before an automatic charge
        if not chassis.low_battery:
            self._auto_tried = False
        elif not self.active and self._auto_charge_due():
            self._auto_tried = True
            try:
                self._execute(TaskRequest(TaskExect.EXECUTE, AUTO_TASK_ID, TaskType.CHARGING),
                              own=True)
                assert self.task is not None
                self.task.msg = "battery low: charging"
                log.info("battery low (%s %%): going to charge", chassis.soc)
            except TaskRefused as exc:
                log.warning("battery low, but cannot go and charge: %s", exc)
        self._refresh()
        return twist

    def _auto_charge_due(self) -> bool:
        ch = self.chassis  # tried once it can be accepted: not before the chassis is up
        return (self.config.auto_charge and not self._auto_tried and not self.docked
                and self.places.charger is not None and ch.initialized and not ch.abnormal())

    def _watch(self, t: Task, ch: Chassis) -> None:
        if t.action.kind == ActionType.CHARGING:
            return  # on the charger: nothing moves; e-stop and faults only show in robot_state
        if ch.link_lost or ch.fault or ch.part_down:
            return self._fail(t, f"{ch.abnormal()}: clear it and send the task again")
        if ch.e_stopped:
            if t.state == TaskState.EXECUTING:
                self._halt(t, TaskState.PAUSED, ESTOP_MSG)
            return None
        if t.state == TaskState.PAUSED and t.msg == ESTOP_MSG:
            t.msg = "the emergency stop was released: continue (3) to go on"
        if ch.critical_battery and t.request.task_type != TaskType.CHARGING:
            return self._fail(t, f"battery critical{pct(ch.soc)}: the task is abandoned")
        if t.state != TaskState.EXECUTING or t.action.kind != ActionType.NAVIGATION:
            return None
        if not ch.localized or ch.pose is None:
            if not t.lost:
                self.nav.cancel(self.now)
                self._lose(t)
        elif t.lost:
            t.lost, t.action_state, t.msg = False, ActionState.EXECUTING, ""
            assert t.action.target is not None
            self._send(t, t.action.target, t.action.poses)
        return None

    def _run(self, t: Task, ch: Chassis, dt: float) -> Twist | None:
        kind = t.action.kind
        if kind in (ActionType.DOCK_IN, ActionType.DOCK_OUT):
            return self._run_dock(t, ch, dt)
        if t.state != TaskState.EXECUTING:
            return (0.0, 0.0) if kind == ActionType.NAVIGATION else None
        if kind == ActionType.NAVIGATION:
            if t.lost or ch.pose is None:
                return (0.0, 0.0)
            fb = self.nav.tick(self.now, ch.pose)
            state = getattr(fb.state, "name", str(fb.state))
            if state == "SUCCEEDED":
                self._next(t)
                return (0.0, 0.0)
            if state in ("ABORTED", "PREEMPTED"):
                self._fail(t, f"navigation {state.lower()}: {fb.reason or fb.status}")
                return (0.0, 0.0)
            if self.blocked.update(blocked(fb.status, fb.reason), self.now):
                t.action_state, t.msg = ActionState.WARNING, f"path blocked: {fb.reason}"
            elif t.action_state == ActionState.WARNING:
                t.action_state, t.msg = ActionState.EXECUTING, ""
            return (fb.linear, fb.angular)
        if kind == ActionType.TRANSPORT:
            t.elapsed += dt
            if t.elapsed + 1e-9 >= t.action.duration:
                self._next(t)
            return None
        if kind == ActionType.CHARGING:
            if not ch.charging:
                self._fail(t, "the charger contact opened while charging")
            elif ch.soc is not None and ch.soc >= self.config.full_soc:
                t.msg = f"charged to {ch.soc:.0f} %: undocking"
                self._next(t)
        return None
