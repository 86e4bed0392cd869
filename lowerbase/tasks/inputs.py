"""The chassis as the tasks node hears it on ROS, without ROS: :class:`ChassisInputs`.

The node's subscribers store the latest of each input here (with the rospy time it arrived);
:meth:`ChassisInputs.chassis` turns them into the machine's :class:`Chassis` every tick:

- ``driver_base/link_state`` (std_msgs/String): ``standby`` / ``ready`` = initialized,
  ``lost`` = link lost (initialized still, once /odom was seen);
- ``status_code`` (std_msgs/UInt64): e-stop (button or command), motor faults and BMS
  protection, low / critical battery (docs/status-codes.md);
- ``/battery`` (woosh_msgs/Battery): ``batteryPercentage`` is the state of charge;
- ``driver_base/bms`` (woosh_msgs/BMS): ``BMSStatus`` CHARGER_CONNECTED is the charger contact;
- ``/odom`` (nav_msgs/Odometry): the pose the step moves run on;
- ``movebase_pose2d`` (geometry_msgs/Pose2D, the world's localization while it runs): the
  robot on the map; localized while one arrived within ``pose_timeout`` s;
- ``lowerbase/localization`` (std_msgs/String, latched, the world's): ``lost: ...`` while the
  estimate does not fit the scans (shown on robot_status, navigation goes on);
- the parameter ``/lowerbase/part_down`` (string, set by ``lowerbase robot``'s supervisor):
  ``"navigation ended (exit code 1): ..."`` while a part of the robot is down ("" none): the
  robot is abnormal, a running task fails. Once robot_status carries it, the node writes it to
  ``/lowerbase/part_reported``, so the supervisor stops the robot only after that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from lowerbase.bms.status import BmsStatus
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.tasks.model import Pose
from lowerbase.tasks.status import Chassis

#: the status bits that stop the motors (a task fails on them)
FAULT_BITS = (StatusBit.LEFT_MOTOR_FAULT, StatusBit.RIGHT_MOTOR_FAULT, StatusBit.BMS_PROTECTION)
ESTOP_BITS = StatusBit.ESTOP_BUTTON | StatusBit.ESTOP_COMMAND
#: the ROS parameters of a crashed part (see the module docstring)
PART_DOWN_PARAM = "/lowerbase/part_down"
PART_REPORTED_PARAM = "/lowerbase/part_reported"
#: [characters] of a part's crash kept for robot_status
PART_NOTE_MAX = 600


def faults_of(code: int) -> str:
    """The motor-stopping faults in a status code, in words ("" none)."""
    return ", ".join(b.name.lower().replace("_", " ") for b in FAULT_BITS
                     if code & b and b.name is not None)


def finite_pose(x: float, y: float, yaw: float) -> Pose | None:
    """(x, y, yaw) when all are finite, else None (a bad message is dropped)."""
    if all(math.isfinite(v) for v in (x, y, yaw)):
        return float(x), float(y), float(yaw)
    return None


@dataclass
class ChassisInputs:
    """The latest chassis inputs (see the module docstring); times are the node's clock."""

    link_state: str | None = None
    status_code: int = 0
    soc: float | None = None
    bms_status: int | None = None
    odom: Pose | None = None
    pose: Pose | None = None
    pose_time: float | None = None
    pose_timeout: float = 1.0  #: [s] without a pose: localization lost
    localization: str = ""  #: the world's lowerbase/localization line ("lost: ..."/"localized")
    part_down: str = ""  #: /lowerbase/part_down: a part of the robot that ended ("" none)

    def localized(self, now: float) -> bool:
        return self.pose_time is not None and now - self.pose_time <= self.pose_timeout

    def chassis(self, now: float) -> Chassis:
        code, link = self.status_code, self.link_state
        localized = self.localized(now)
        return Chassis(
            initialized=link in ("standby", "ready") or (link == "lost" and self.odom is not None),
            link_lost=link == "lost",
            e_stopped=bool(code & ESTOP_BITS),
            fault=faults_of(code),
            soc=self.soc,
            low_battery=bool(code & StatusBit.LOW_BATTERY),
            critical_battery=bool(code & StatusBit.CRITICAL_BATTERY),
            charging=self.bms_status is not None
            and bool(self.bms_status & BmsStatus.CHARGER_CONNECTED),
            localized=localized,
            uncertain=self.localization if self.localization.startswith("lost") else "",
            part_down=self.part_down,
            pose=self.pose,
            odom=self.odom)
