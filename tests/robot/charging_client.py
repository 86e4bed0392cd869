#!/usr/bin/env python3
"""A user's charging task through the vendor's interface only (shared/seeds/000): the
exec_task service, the robot_status topic and /battery (woosh_msgs/Battery).

It sends a charging task (task_type 3), waits until the robot charges (robot_state 8, the
charging action) and /battery shows it (chargeStatus charging, batteryCurrent > 0, the
remaining capacity rising), then sends a parking task to ``--mark``, which undocks the robot
first, and waits for that task's end. Every robot_status and the /battery samples that decided
something are printed as ``robot_status {json}`` / ``battery {json}`` lines; the exit code is 0
when the parking task completed, 1 when a request was refused or a task failed, 2 on a timeout.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from collections.abc import Callable
from typing import Any

import rospy
from woosh_msgs.msg import Battery, RobotStatus
from woosh_msgs.srv import ExecTask

EXECUTE, CHARGING_TASK, PARKING_TASK = 1, 3, 2
COMPLETED, CANCELLED, FAILED = 7, 8, 9
UNINITIALIZED, CHARGING_STATE = 1, 8
CHARGING_ACTION = 7
CHARGE_STATUS_CHARGING = 1


def fields(msg: Any) -> dict[str, Any]:
    return {k: getattr(msg, k) for k in msg.__slots__ if k != "header"}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--task-id", type=int, default=31, help="the charging task's id")
    p.add_argument("--mark", default="start", help="the parking task's target (mark_no)")
    p.add_argument("--rise", type=float, default=0.02,
                   help="[Ah] how much capacityRemain must rise while charging")
    p.add_argument("--timeout", type=float, default=240.0, help="[s] for each wait")
    args = p.parse_args(rospy.myargv()[1:])

    rospy.init_node("charging_task", anonymous=True)
    changed = threading.Condition()
    statuses: list[Any] = []
    battery: list[Any] = []

    def on_status(msg: Any) -> None:
        print("robot_status " + json.dumps(fields(msg)), flush=True)
        with changed:
            statuses.append(msg)
            changed.notify_all()

    def on_battery(msg: Any) -> None:
        with changed:
            battery.append(msg)
            del battery[:-1]
            changed.notify_all()

    def wait(cond: Callable[[], bool], what: str) -> bool:
        with changed:
            if changed.wait_for(cond, args.timeout):
                return True
        print(f"timeout: {what} not seen within {args.timeout:g} s", file=sys.stderr)
        return False

    def status_is(cond: Callable[[Any], bool]) -> Callable[[], bool]:
        return lambda: bool(statuses) and cond(statuses[-1])

    def ended(task_id: int) -> Callable[[Any], bool]:
        return lambda s: s.task_id == task_id and s.task_state in (COMPLETED, CANCELLED, FAILED)

    def show_battery(what: str) -> Any:
        b = battery[-1]
        print("battery " + json.dumps({"when": what, **fields(b)}), flush=True)
        return b

    rospy.Subscriber("robot_status", RobotStatus, on_status, queue_size=100)
    rospy.Subscriber("battery", Battery, on_battery, queue_size=10)
    rospy.wait_for_service("exec_task", timeout=args.timeout)
    if not wait(status_is(lambda s: s.robot_state != UNINITIALIZED), "an initialized robot") \
            or not wait(lambda: bool(battery), "/battery"):
        return 2
    with changed:
        show_battery("before")
    exec_task = rospy.ServiceProxy("exec_task", ExecTask)

    def execute(**request: Any) -> bool:
        res = exec_task(task_exect=EXECUTE, **request)
        print("exec_task " + json.dumps({"success": res.success, "message": res.message,
                                         "statusCode": res.statusCode}), flush=True)
        return bool(res.success)

    if not execute(task_id=args.task_id, task_type=CHARGING_TASK):
        return 1
    # the robot drives to the charger, docks, and the BMS reports the charger
    if not wait(status_is(lambda s: (s.task_id == args.task_id and s.robot_state == CHARGING_STATE
                                     and s.action_type == CHARGING_ACTION) or ended(
                                         args.task_id)(s)), "the charging action"):
        return 2
    if statuses[-1].task_state in (COMPLETED, CANCELLED, FAILED):
        return 1
    if not wait(lambda: battery[-1].chargeStatus == CHARGE_STATUS_CHARGING
                and battery[-1].batteryCurrent > 0, "/battery charging"):
        return 2
    with changed:
        first = show_battery("charging")
    if not wait(lambda: battery[-1].capacityRemain >= first.capacityRemain + args.rise
                or ended(args.task_id)(statuses[-1]), "the charge rising"):
        return 2
    with changed:
        show_battery("charged")
    if ended(args.task_id)(statuses[-1]):
        return 1
    # a new task: the charging task ends, the robot undocks and parks
    if not execute(task_id=args.task_id + 1, task_type=PARKING_TASK, mark_no=args.mark):
        return 1
    if not wait(status_is(ended(args.task_id + 1)), "the parking task's end"):
        return 2
    if not wait(lambda: battery[-1].chargeStatus != CHARGE_STATUS_CHARGING
                and battery[-1].batteryCurrent < 0, "/battery discharging"):
        return 2
    with changed:
        show_battery("after")
    return 0 if statuses[-1].task_state == COMPLETED else 1


if __name__ == "__main__":
    sys.exit(main())
