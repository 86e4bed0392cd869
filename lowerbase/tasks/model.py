"""The vendor's task vocabulary (shared/seeds/000, woosh_msgs ExecTask.srv / RobotStatus.msg).

The enums carry the seed's numeric codes; :class:`TaskRequest`, :class:`TaskResponse` and
:class:`Status` are ExecTask's request/response and RobotStatus without ROS. Poses are
``(x, y, yaw)`` in the map frame [m, rad].
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

Pose = tuple[float, float, float]


class TaskExect(enum.IntEnum):
    """ExecTask ``task_exect``: what a request asks for."""

    EXECUTE = 1
    PAUSE = 2
    CONTINUE = 3
    CANCEL = 4
    WAIT = 6  #: wait for interruption


class TaskType(enum.IntEnum):
    UNDEFINED = 0
    PICKING = 1
    PARKING = 2
    CHARGING = 3
    TRANSPORTING = 4


class Direction(enum.IntEnum):
    UNDEFINED = 0  #: not a load/unload task
    LOAD = 1
    UNLOAD = 2


class TaskState(enum.IntEnum):
    UNDEFINED = 0
    EXECUTING = 3
    PAUSED = 4
    WAITING = 5  #: waiting for action
    COMPLETED = 7
    CANCELLED = 8
    FAILED = 9


class ActionType(enum.IntEnum):
    UNDEFINED = 0
    NAVIGATION = 1
    STEP_CONTROL = 2  #: single-step control
    DOCK_IN = 3  #: secondary positioning entry
    DOCK_OUT = 4  #: secondary positioning exit
    TRANSPORT = 5  #: the load/unload action
    WAITING = 6
    CHARGING = 7


class ActionState(enum.IntEnum):
    UNDEFINED = 0
    EXECUTING = 1
    WARNING = 2
    CANCELLED = 3
    COMPLETED = 4
    FAILED = 5
    PAUSED = 10
    TRAFFIC_CONTROL = 11


class RobotState(enum.IntEnum):
    """RobotStatus ``robot_state`` and ExecTask's response ``statusCode``."""

    UNDEFINED = 0
    UNINITIALIZED = 1
    IDLE = 2
    PARKING = 3
    TASK = 4  #: on a mission
    WARNING = 5
    ABNORMAL = 6
    CHARGING = 8
    MAPPING = 9  #: composing a map (never set here: mapping is not emulated)


class RobotMode(enum.IntEnum):
    UNDEFINED = 0
    AUTOMATIC = 1
    MANUAL = 2
    MAINTENANCE = 3


class WorkMode(enum.IntEnum):
    UNDEFINED = 0
    DEPLOYMENT = 1
    TASK = 2
    SCHEDULING = 3


#: task states in which a task is over
FINAL_STATES = (TaskState.COMPLETED, TaskState.CANCELLED, TaskState.FAILED)
#: the task id the robot uses for the charging it starts on its own (low battery)
AUTO_TASK_ID = 0


@dataclass(frozen=True)
class TaskRequest:
    """An ExecTask request (ROS-free): ``poses`` in the map frame."""

    task_exect: int
    task_id: int
    task_type: int = 0
    direction: int = 0
    task_type_no: int = 0
    mark_no: str = ""
    poses: tuple[Pose, ...] = ()
    custom: int = 0


@dataclass(frozen=True)
class TaskResponse:
    """An ExecTask response: ``status_code`` is the robot state after the request."""

    success: bool
    message: str
    status_code: int


@dataclass(frozen=True)
class Status:
    """A woosh_msgs/RobotStatus (ROS-free). Equality ignores ``time``: a status is published
    when anything else changed."""

    task_id: int = 0
    task_type: int = TaskType.UNDEFINED
    task_state: int = TaskState.UNDEFINED
    action_type: int = ActionType.UNDEFINED
    action_state: int = ActionState.UNDEFINED
    robot_state: int = RobotState.UNINITIALIZED
    robot_mode: int = RobotMode.AUTOMATIC
    work_mode: int = WorkMode.TASK
    wait_id: int = 0
    dest: str = ""
    msg: str = ""
    time: int = field(default=0, compare=False)

    def fields(self) -> dict[str, int | str]:
        """The RobotStatus message fields."""
        return {name: getattr(self, name) for name in (
            "task_id", "task_type", "task_state", "action_type", "action_state",
            "robot_state", "robot_mode", "work_mode", "wait_id", "dest", "msg", "time")}
