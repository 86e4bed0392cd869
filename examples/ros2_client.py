#!/usr/bin/env python3
"""A team's own rclpy node against the virtual robot on ROS 2: nav2's NavigateToPose goals,
then a transport task through the vendor's exec_task and robot_status (shared/seeds/000).

Start the robot first, from the ROS 2 venv (``make ros2``; docs/ros2.md)::

    eval "$(.venv-ros2/bin/lowerbase ros2-env)"; export ROS_DOMAIN_ID=42
    lowerbase robot --ros2 --map empty_room &
    python examples/ros2_client.py --goal 6.0 4.0 0.0 --goal 7.0 5.0 1.57 --mark R1

The node runs on the robot's simulated time (``use_sim_time`` true: /clock). It prints one
``navigate {json}`` line per goal and one ``robot_status {json}`` line per status of the task,
and exits 0 when every goal SUCCEEDED and the task COMPLETED; 1 when one did not; 2 when
something did not come within ``--timeout`` seconds of wall time.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from typing import Any

import rclpy
from nav2_msgs.action import NavigateToPose
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from woosh_msgs.msg import RobotStatus
from woosh_msgs.srv import ExecTask

SUCCEEDED = 4  # action_msgs/GoalStatus
COMPLETED, CANCELLED, FAILED = 7, 8, 9  # woosh_msgs/RobotStatus task_state
UNINITIALIZED = 1  # woosh_msgs/RobotStatus robot_state
TRANSPORT = 4  # exec_task's task_type


class TimedOut(Exception):
    pass


def spin_until(node: Node, done: Callable[[], bool], what: str, deadline: float) -> None:
    while not done():
        if time.monotonic() > deadline:
            raise TimedOut(what)
        rclpy.spin_once(node, timeout_sec=0.1)


def navigate(node: Node, client: ActionClient, x: float, y: float, yaw: float,
             deadline: float) -> bool:
    goal = NavigateToPose.Goal()
    goal.pose.header.frame_id = "map"
    goal.pose.pose.position.x, goal.pose.pose.position.y = x, y
    goal.pose.pose.orientation.z, goal.pose.pose.orientation.w = math.sin(yaw / 2), \
        math.cos(yaw / 2)
    feedback: list[Any] = []
    sent = client.send_goal_async(goal, feedback_callback=lambda m: feedback.append(m.feedback))
    spin_until(node, sent.done, "the goal's acceptance", deadline)
    handle = sent.result()
    if not handle.accepted:
        print("navigate " + json.dumps({"goal": [x, y, yaw], "accepted": False}), flush=True)
        return False
    result = handle.get_result_async()
    spin_until(node, result.done, "the goal's end", deadline)
    end = result.result()
    last = feedback[-1] if feedback else None
    print("navigate " + json.dumps({
        "goal": [x, y, yaw], "status": end.status, "error_code": end.result.error_code,
        "feedbacks": len(feedback),
        "distance_remaining": None if last is None else round(last.distance_remaining, 3)}),
        flush=True)
    return bool(end.status == SUCCEEDED)


def transport(node: Node, mark: str, direction: int, deadline: float) -> bool:
    statuses: list[RobotStatus] = []

    def on_status(msg: RobotStatus) -> None:
        statuses.append(msg)
        print("robot_status " + json.dumps({
            "robot_state": msg.robot_state, "task_id": msg.task_id,
            "task_state": msg.task_state, "dest": msg.dest}), flush=True)

    # robot_status is latched on ROS 1: reliable and transient local on ROS 2
    node.create_subscription(RobotStatus, "/robot_status", on_status, QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    client = node.create_client(ExecTask, "/exec_task")
    spin_until(node, lambda: client.service_is_ready() and bool(statuses)
               and statuses[-1].robot_state != UNINITIALIZED,
               "exec_task and an initialized robot", deadline)
    task_id = int(time.time()) % 100000
    call = client.call_async(ExecTask.Request(task_exect=1, task_id=task_id,
                                              task_type=TRANSPORT, direction=direction,
                                              mark_no=mark))
    spin_until(node, call.done, "exec_task's answer", deadline)
    if not call.result().success:
        print(f"exec_task refused: {call.result().message}", file=sys.stderr)
        return False
    spin_until(node, lambda: statuses[-1].task_id == task_id
               and statuses[-1].task_state in (COMPLETED, CANCELLED, FAILED),
               "the task's end", deadline)
    return statuses[-1].task_state == COMPLETED


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--goal", nargs=3, type=float, action="append", default=[],
                    metavar=("X", "Y", "YAW"), help="a NavigateToPose goal in the map frame "
                    "[m, m, rad]; repeatable, sent in order")
    ap.add_argument("--mark", help="then a transport task to this storage point (e.g. R1)")
    ap.add_argument("--direction", type=int, default=2, choices=(1, 2),
                    help="the task's action at the mark: 1 loading, 2 unloading (default)")
    ap.add_argument("--timeout", type=float, default=600.0,
                    help="[s] of wall time for everything (default 600)")
    args = ap.parse_args(argv)
    rclpy.init()
    node = rclpy.create_node("ros2_client", parameter_overrides=[
        Parameter("use_sim_time", Parameter.Type.BOOL, True)])
    deadline = time.monotonic() + args.timeout
    ok = True
    try:
        nav = ActionClient(node, NavigateToPose, "/navigate_to_pose")
        if args.goal:
            spin_until(node, nav.server_is_ready, "the navigate_to_pose server", deadline)
        for x, y, yaw in args.goal:
            ok = navigate(node, nav, x, y, yaw, deadline) and ok
        if args.mark:
            ok = transport(node, args.mark, args.direction, deadline) and ok
    except TimedOut as exc:
        print(f"ros2_client: {exc} did not come within {args.timeout:g} s", file=sys.stderr)
        return 2
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
