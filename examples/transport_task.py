#!/usr/bin/env python3
"""A transport task through the vendor's interface only (shared/seeds/000): the exec_task
service and the robot_status topic.

Start the virtual robot first (``lowerbase robot --map empty_room``), then, with the same
ROS_MASTER_URI::

    .venv/bin/python examples/transport_task.py --mark R1 --direction 2

It waits until the robot is initialized, sends a transporting task (task_type 4) to the storage
point ``--mark`` with an unloading (2) or loading (1) action, prints every robot_status as one
``robot_status {json}`` line, and exits 0 when the task completed (1 when it failed, was
cancelled or was refused, 2 on a timeout).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading

import rospy
from woosh_msgs.msg import RobotStatus
from woosh_msgs.srv import ExecTask

COMPLETED, CANCELLED, FAILED = 7, 8, 9
UNINITIALIZED = 1


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--mark", default="R1", help="the storage point (mark_no)")
    p.add_argument("--task-id", type=int, default=1)
    p.add_argument("--direction", type=int, default=2, help="1 load, 2 unload, 0 none")
    p.add_argument("--timeout", type=float, default=300.0, help="[s] for the whole task")
    args = p.parse_args(rospy.myargv()[1:])

    rospy.init_node("transport_task", anonymous=True)
    changed = threading.Condition()
    last: list[RobotStatus] = []

    def on_status(msg: RobotStatus) -> None:
        fields = {k: getattr(msg, k) for k in msg.__slots__}
        print("robot_status " + json.dumps(fields), flush=True)
        with changed:
            last.append(msg)
            changed.notify_all()

    def wait(condition, what: str) -> bool:
        with changed:
            if changed.wait_for(lambda: bool(last) and condition(last[-1]), args.timeout):
                return True
        print(f"timeout: {what} not seen within {args.timeout:g} s", file=sys.stderr)
        return False

    rospy.Subscriber("robot_status", RobotStatus, on_status, queue_size=100)
    rospy.wait_for_service("exec_task", timeout=args.timeout)
    if not wait(lambda s: s.robot_state != UNINITIALIZED, "an initialized robot"):
        return 2
    exec_task = rospy.ServiceProxy("exec_task", ExecTask)
    res = exec_task(task_exect=1, task_id=args.task_id, task_type=4, direction=args.direction,
                    mark_no=args.mark)
    print("exec_task " + json.dumps({"success": res.success, "message": res.message,
                                     "statusCode": res.statusCode}), flush=True)
    if not res.success:
        return 1
    if not wait(lambda s: s.task_id == args.task_id
                and s.task_state in (COMPLETED, CANCELLED, FAILED), "the task's end"):
        return 2
    return 0 if last[-1].task_state == COMPLETED else 1


if __name__ == "__main__":
    sys.exit(main())
