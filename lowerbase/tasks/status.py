"""robot_state from the chassis and the task, and robot_status published only on change."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

from lowerbase.tasks.model import Pose, RobotState, Status, TaskType


@dataclass(frozen=True)
class Chassis:
    """What the task machine reads of the chassis (driver_base, localization) each tick."""

    initialized: bool = True  #: the lower computer's link is up and configured
    #: a part of the robot that ended, in words from its supervisor ("" none)
    part_down: str = ""
    link_lost: bool = False  #: no Heartbeat within the driver's link timeout
    e_stopped: bool = False
    fault: str = ""  #: a fault that stops the motors, in words ("" none)
    soc: float | None = 100.0  #: state of charge [%], None: no BMS reading yet
    low_battery: bool = False
    critical_battery: bool = False
    charging: bool = False  #: the BMS reports a connected charger
    localized: bool = True  #: the localizer's estimate can be trusted
    #: the localization's own doubt ("lost: the scan fits the map at 20 % ..."; "" none)
    uncertain: str = ""
    pose: Pose | None = None  #: the robot on the map (localization)
    odom: Pose | None = None  #: /odom (the step moves run closed loop on it)

    def abnormal(self) -> str:
        """Why the chassis cannot move on its own ("" when it can)."""
        if self.part_down:
            return self.part_down
        if self.link_lost:
            return "the lower computer's link is lost"
        if self.e_stopped:
            return "the emergency stop is on"
        if self.fault:
            return f"chassis fault: {self.fault}"
        return ""


def robot_state(ch: Chassis, task_type: int | None, warning: bool) -> RobotState:
    """robot_state (and ExecTask's statusCode), in this order: abnormal (a part of the robot
    ended); uninitialized; abnormal (link lost, e-stop, fault); charging (the BMS sees the
    charger); abnormal (critical battery); warning (low battery, localization lost, a warning
    of the running action); parking (a parking task runs); on a task (any other task runs);
    idle. ``task_type`` is the running task's type, None when no task runs."""
    if ch.part_down:
        return RobotState.ABNORMAL
    if not ch.initialized:
        return RobotState.UNINITIALIZED
    if ch.abnormal():
        return RobotState.ABNORMAL
    if ch.charging:
        return RobotState.CHARGING
    if ch.critical_battery:
        return RobotState.ABNORMAL
    if ch.low_battery or not ch.localized or warning:
        return RobotState.WARNING
    if task_type == TaskType.PARKING:
        return RobotState.PARKING
    if task_type is not None:
        return RobotState.TASK
    return RobotState.IDLE


class StatusTracker:
    """Keeps the last robot_status; :meth:`update` stamps and publishes a status only when a
    field other than ``time`` differs from the last one."""

    def __init__(self, publish: Callable[[Status], None] | None = None, *,
                 keep: int = 10000) -> None:
        self.publish = publish
        self.current: Status | None = None
        #: the last ``keep`` published statuses, in order
        self.history: deque[Status] = deque(maxlen=keep)

    def update(self, status: Status, now: float) -> bool:
        if status == self.current:
            return False
        stamped = replace(status, time=int(now))
        self.current = stamped
        self.history.append(stamped)
        if self.publish is not None:
            self.publish(stamped)
        return True
