"""ChassisInputs: the tasks node's chassis from driver_base's and the world's topics (ROS-free),
checked against the same rows chassis_from_driver (TaskSim) reads from the driver core."""

from __future__ import annotations

import math

from lowerbase.bms.status import BmsStatus
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.tasks.inputs import ChassisInputs, faults_of, finite_pose
from lowerbase.tasks.model import RobotState
from lowerbase.tasks.status import robot_state


def test_link_states() -> None:
    inp = ChassisInputs()
    assert not inp.chassis(0.0).initialized  # nothing heard yet
    for link, init in (("waiting", False), ("configuring", False), ("standby", True),
                       ("ready", True)):
        inp.link_state = link
        ch = inp.chassis(0.0)
        assert ch.initialized is init and not ch.link_lost, link
    inp.link_state = "lost"
    assert inp.chassis(0.0).link_lost and not inp.chassis(0.0).initialized  # never had /odom
    inp.odom = (0.0, 0.0, 0.0)
    ch = inp.chassis(0.0)
    assert ch.link_lost and ch.initialized
    assert robot_state(ch, None, False) == RobotState.ABNORMAL


def test_status_code_bits_and_battery() -> None:
    inp = ChassisInputs(link_state="ready")
    assert inp.chassis(0.0).soc is None
    inp.status_code = int(StatusBit.ESTOP_COMMAND)
    assert inp.chassis(0.0).e_stopped and inp.chassis(0.0).abnormal()
    inp.status_code = int(StatusBit.ESTOP_BUTTON | StatusBit.LEFT_MOTOR_FAULT
                          | StatusBit.BMS_PROTECTION | StatusBit.LOW_BATTERY)
    ch = inp.chassis(0.0)
    assert ch.e_stopped and ch.fault == "left motor fault, bms protection" and ch.low_battery
    assert not ch.critical_battery
    inp.status_code = int(StatusBit.CRITICAL_BATTERY | StatusBit.IMU_FAULT)
    ch = inp.chassis(0.0)
    assert ch.critical_battery and ch.fault == "" and not ch.e_stopped  # IMU: not a stop
    assert faults_of(int(StatusBit.RIGHT_MOTOR_FAULT)) == "right motor fault"
    inp.soc, inp.bms_status = 42.0, int(BmsStatus.CHARGER_CONNECTED)
    ch = inp.chassis(0.0)
    assert ch.soc == 42.0 and ch.charging
    inp.bms_status = 0
    assert not inp.chassis(0.0).charging


def test_localized_while_poses_arrive() -> None:
    inp = ChassisInputs(link_state="ready", pose_timeout=1.0)
    assert not inp.chassis(5.0).localized
    inp.pose, inp.pose_time = (1.0, 2.0, 0.5), 10.0
    assert inp.chassis(10.9).localized and inp.chassis(10.9).pose == (1.0, 2.0, 0.5)
    ch = inp.chassis(11.2)
    assert not ch.localized and ch.pose == (1.0, 2.0, 0.5)  # the last one, not trusted
    assert robot_state(ch, None, False) == RobotState.WARNING
    assert finite_pose(1.0, math.nan, 0.0) is None and finite_pose(1, 2, 3) == (1.0, 2.0, 3.0)
