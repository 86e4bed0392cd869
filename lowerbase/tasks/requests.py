"""The exec_task side of the task machine: :class:`Requests`, a mixin of
:class:`~lowerbase.tasks.machine.TaskMachine`.

:meth:`Requests.request` answers one ExecTask request: execute (checked against the chassis,
the running task and the map's places, then planned), pause, continue, cancel and wait for
interruption. A refusal is a :class:`~lowerbase.tasks.plan.TaskRefused` whose text is the
response's ``message``; it changes nothing. docs/tasks.md has the table.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from lowerbase.tasks.model import (
    ActionState,
    ActionType,
    RobotState,
    TaskExect,
    TaskRequest,
    TaskResponse,
    TaskState,
    TaskType,
)
from lowerbase.tasks.plan import Action, TaskConfig, TaskRefused, plan
from lowerbase.tasks.status import Chassis
from lowerbase.tasks.task import Task, pct
from lowerbase.world.places import Places

log = logging.getLogger(__name__)


class Requests:
    """exec_task requests on the machine (which provides the attributes below)."""

    places: Places
    config: TaskConfig
    chassis: Chassis
    docked: bool
    task: Task | None
    now: float
    _wait_ids: int

    if TYPE_CHECKING:  # TaskMachine's
        def _refresh(self) -> None: ...

        def robot_state(self) -> RobotState: ...

        def _start(self, t: Task) -> None: ...

        def _stop(self, t: Task, state: TaskState, action_state: ActionState,
                  msg: str) -> None: ...

        def _halt(self, t: Task, state: TaskState, msg: str) -> None: ...

        def _resume(self, t: Task) -> None: ...

    def request(self, req: TaskRequest, now: float) -> TaskResponse:
        """Answer an ExecTask request (refusals: success False and why in ``message``)."""
        self.now = now
        try:
            message, ok = self._handle(req), True
        except TaskRefused as exc:
            message, ok = str(exc), False
            log.info("exec_task refused: %s", message)
        self._refresh()
        return TaskResponse(ok, message, int(self.robot_state()))

    def _handle(self, req: TaskRequest) -> str:
        verbs = {2: "pause", 3: "continue", 4: "cancel", 6: "wait"}
        if req.task_exect == TaskExect.EXECUTE:
            return self._execute(req)
        if req.task_exect not in verbs:
            raise TaskRefused(f"unknown task_exect {req.task_exect}: 1 execute, 2 pause, "
                              "3 continue, 4 cancel, 6 wait for interruption")
        t = self.task
        if t is None or not t.active:
            raise TaskRefused(f"no task is running: nothing to {verbs[req.task_exect]}")
        tid = t.request.task_id
        if req.task_id != tid:
            raise TaskRefused(f"task {req.task_id} is not the running task: that is {tid}")
        charging = t.action.kind == ActionType.CHARGING
        if req.task_exect == TaskExect.CANCEL:
            self._stop(t, TaskState.CANCELLED, ActionState.CANCELLED, "cancelled by request")
            return f"task {tid} cancelled"
        if req.task_exect == TaskExect.CONTINUE:
            if t.state == TaskState.EXECUTING:
                raise TaskRefused(f"task {tid} is not paused: nothing to continue")
            why = self.chassis.abnormal()
            if why:
                raise TaskRefused(f"{why}: clear it first, then continue")
            self._resume(t)
            return f"task {tid} continues"
        if charging:
            raise TaskRefused(f"task {tid} is charging, which cannot be paused: cancel it (4) "
                              "or send a new task")
        if t.state != TaskState.EXECUTING:
            raise TaskRefused(f"task {tid} is {t.state.name.lower()} already: continue (3) or "
                              "cancel (4) it")
        if req.task_exect == TaskExect.PAUSE:
            self._halt(t, TaskState.PAUSED, "paused by request")
            return f"task {tid} paused"
        self._wait_ids += 1
        t.wait_id = self._wait_ids
        self._halt(t, TaskState.WAITING, "waiting for interruption: continue (3) to go on")
        t.action_state = ActionState.EXECUTING
        return f"task {tid} waits (wait_id {t.wait_id})"

    def _execute(self, req: TaskRequest, own: bool = False) -> str:
        ch = self.chassis
        if ch.part_down:
            raise TaskRefused(f"{ch.part_down}: the robot needs it, restart the robot")
        if not ch.initialized:
            raise TaskRefused("the chassis is not initialized: wait until driver_base has "
                              "configured the lower computer")
        if ch.abnormal():
            raise TaskRefused(f"{ch.abnormal()}: clear it, then send the task again")
        t = self.task
        if t is not None and t.active and t.action.kind != ActionType.CHARGING:
            tid = t.request.task_id
            if tid == req.task_id:
                raise TaskRefused(f"task {tid} is already running")
            raise TaskRefused(f"task {tid} is {t.state.name.lower()}: cancel it (4) first")
        if ch.critical_battery and req.task_type != TaskType.CHARGING:
            raise TaskRefused(f"the battery is critical{pct(ch.soc)}: send a charging "
                              "task (task_type 3) first")
        if own:
            req_checked = TaskRequest(req.task_exect, 1, req.task_type)
            actions, dest = plan(req_checked, self.places, self.config)
        else:
            actions, dest = plan(req, self.places, self.config)
        if self.docked:
            if req.task_type == TaskType.CHARGING:
                actions = [a for a in actions if a.kind in (ActionType.CHARGING,
                                                            ActionType.DOCK_OUT)]
            else:
                actions.insert(0, Action(ActionType.DOCK_OUT))
        new = Task(req, actions, dest)
        self._start(new)
        if new.state == TaskState.FAILED:
            raise TaskRefused(new.msg)
        if t is not None and t.active:  # charging: ended by the new task
            t.state, t.action_state = TaskState.COMPLETED, ActionState.COMPLETED
            t.msg = f"charging ended{pct(ch.soc)} for task {req.task_id}"
            self._refresh()
        self.task = new
        return f"task {req.task_id} accepted: {TaskType(req.task_type).name.lower()} to {dest}"
