"""A task in the machine, and what the machine needs of navigation.

- :class:`Task`: one accepted exec_task request, its actions and where it is in them;
- :class:`Navigation` / :class:`NavFeedback`: the navigator in-process (TaskSim) or the
  /move_base action client (:mod:`lowerbase.tasks.ros_clients`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from lowerbase.tasks.model import FINAL_STATES, ActionState, Pose, TaskRequest, TaskState
from lowerbase.tasks.plan import Action

Twist = tuple[float, float]
#: a task paused by the emergency stop says so in robot_status' msg
ESTOP_MSG = "the emergency stop is on: release it, then continue (3)"


class NavFeedback(Protocol):
    """What a navigation tick returns (the Navigator's NavCommand)."""

    @property
    def linear(self) -> float: ...

    @property
    def angular(self) -> float: ...

    @property
    def state(self) -> Any: ...  # a ``name``: PENDING ACTIVE SUCCEEDED ABORTED PREEMPTED

    @property
    def status(self) -> Any: ...

    @property
    def reason(self) -> str: ...


class Navigation(Protocol):
    """What the task machine needs of navigation."""

    def send_goal(self, target: Pose, poses: Sequence[Pose] = (), execution_mode: int = 0,
                  now: float = 0.0) -> None: ...

    def cancel(self, now: float) -> None: ...

    def tick(self, now: float, pose: Pose) -> NavFeedback: ...


def pct(soc: float | None) -> str:
    """The charge for messages: ' (80 %)', or '' when unknown."""
    return "" if soc is None else f" ({soc:.0f} %)"


@dataclass
class Task:
    """One accepted execute request: its actions, the current one (``index``) and its state."""

    request: TaskRequest
    actions: list[Action]
    dest: str
    state: TaskState = TaskState.EXECUTING
    index: int = 0
    action_state: ActionState = ActionState.EXECUTING
    msg: str = ""
    wait_id: int = 0
    elapsed: float = 0.0  #: [s] into a timed action
    contact_wait: float | None = None  #: [s] docked, waiting for the charger this long
    lost: bool = False  #: navigation held while localization is lost
    dock_corrections: int = 0  #: dock-in moves planned again so far (lowerbase.tasks.docking)
    dock_elapsed: float = 0.0  #: [s] the current docking moves have run

    @property
    def action(self) -> Action:
        return self.actions[min(self.index, len(self.actions) - 1)]

    @property
    def active(self) -> bool:
        return self.state not in FINAL_STATES
