#!/usr/bin/env python3
"""Random move_base goals and a transport task against the lockstep robot, through the
vendor's interface only (/map, /move_base, exec_task, robot_status, /amcl_pose).

Start the robot first, then run this with the same ROS_MASTER_URI (the venv's python, which
sees woosh_msgs and lowerbase_sim_msgs)::

    lowerbase robot --sim-time --speed max --map warehouse            # free-running
    .venv/bin/python examples/sim_goals.py --goals 20 --mark A2-01

    lowerbase robot --sim-time --speed max --paused --map warehouse   # reproducible
    .venv/bin/python examples/sim_goals.py --goals 20 --mark A2-01 --step

The goals are drawn with ``--seed`` from the free cells of /map at least ``--clearance`` from
any wall, each one checked with /move_base/make_plan, so the same seed gives the same goals.
With ``--step`` the robot is paused and this client moves its clock: it sends a goal, waits
until move_base has taken it, then calls /lowerbase/step until the goal is done, so every
goal starts at the same simulated instant on a busy host as on an idle one. It prints one
line per goal and ``--report FILE`` writes everything (goals, results, the estimate after
each, every robot_status) as JSON. Exit 0 when every goal SUCCEEDED and the task completed.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import sys
import threading
import time
from typing import Any

import actionlib
import numpy as np
import rospy
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid
from nav_msgs.srv import GetPlan
from scipy.ndimage import distance_transform_edt
from woosh_msgs.msg import MoveBaseAction, MoveBaseGoal, RobotStatus
from woosh_msgs.srv import ExecTask

SUCCEEDED, PENDING = 3, 0
COMPLETED, CANCELLED, FAILED = 7, 8, 9


def pose_stamped(x: float, y: float, yaw: float) -> PoseStamped:
    p = PoseStamped()
    p.header.frame_id = "map"
    p.header.stamp = rospy.Time.now()
    p.pose.position.x, p.pose.position.y = x, y
    p.pose.orientation.z, p.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return p


def draw_goals(grid: OccupancyGrid, n: int, seed: int, clearance: float) -> list[tuple]:
    """``n`` goals on free cells at least ``clearance`` [m] from anything not free, each with
    a plan from the previous one (make_plan), drawn with ``seed``."""
    info = grid.info
    cells = np.array(grid.data, dtype=np.int16).reshape(info.height, info.width)
    free = distance_transform_edt(cells == 0) * info.resolution >= clearance
    ys, xs = np.nonzero(free)
    rng = random.Random(seed)
    make_plan = rospy.ServiceProxy("/move_base/make_plan", GetPlan)
    goals: list[tuple] = []
    start = None
    for _ in range(50 * n):
        if len(goals) == n:
            break
        k = rng.randrange(len(xs))
        x = info.origin.position.x + (xs[k] + 0.5) * info.resolution
        y = info.origin.position.y + (ys[k] + 0.5) * info.resolution
        yaw = rng.uniform(-math.pi, math.pi)
        goal = (round(float(x), 3), round(float(y), 3), round(yaw, 4))
        if start is not None:
            plan = make_plan(start=pose_stamped(*start), goal=pose_stamped(*goal), tolerance=0.0)
            if not plan.plan.poses:
                continue
        goals.append(goal)
        start = goal
    return goals


class Clock:
    """/lowerbase/step when ``step`` (the robot paused), else ROS time."""

    def __init__(self, step: bool) -> None:
        self.step = None
        if step:
            from lowerbase_sim_msgs.srv import Step

            rospy.wait_for_service("/lowerbase/step", timeout=30.0)
            self.step = rospy.ServiceProxy("/lowerbase/step", Step)

    def run(self, seconds: float, until: str) -> float:
        """[s] the simulated time now: where the step stopped (this node's ROS time may
        not have had that /clock message yet), else ROS time."""
        if self.step is None:
            return rospy.get_time()
        res = self.step(seconds=seconds, until=until)
        if not res.success:
            raise SystemExit(f"/lowerbase/step refused: {res.message}")
        return float(res.sim_time)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--goals", type=int, default=20)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--clearance", type=float, default=0.8, help="[m] from walls and racks")
    p.add_argument("--mark", default="A2-01", help="the transport task's storage point")
    p.add_argument("--timeout", type=float, default=180.0, help="[s of sim time] per goal")
    p.add_argument("--step", action="store_true", help="move the paused robot's clock")
    p.add_argument("--report", help="write the results as JSON there")
    args = p.parse_args(rospy.myargv()[1:])

    rospy.init_node("sim_goals", anonymous=True)
    clock = Clock(args.step)
    statuses: list[dict[str, Any]] = []
    estimate: list[Any] = [None]
    lock = threading.Lock()

    def on_status(msg: RobotStatus) -> None:
        with lock:
            statuses.append({k: getattr(msg, k) for k in msg.__slots__})

    def on_pose(msg: PoseWithCovarianceStamped) -> None:
        q = msg.pose.pose.orientation
        estimate[0] = (msg.pose.pose.position.x, msg.pose.pose.position.y,
                       2 * math.atan2(q.z, q.w))

    rospy.Subscriber("robot_status", RobotStatus, on_status, queue_size=1000)
    rospy.Subscriber("/amcl_pose", PoseWithCovarianceStamped, on_pose, queue_size=10)
    grid = rospy.wait_for_message("/map", OccupancyGrid, timeout=30.0)
    client = actionlib.SimpleActionClient("/move_base", MoveBaseAction)
    if not client.wait_for_server(rospy.Duration(30.0)):
        print("no /move_base", file=sys.stderr)
        return 2
    t_start = clock.run(2.0, "")  # localized and ready
    wall_start = time.monotonic()
    goals = draw_goals(grid, args.goals, args.seed, args.clearance)
    results = []
    for i, goal in enumerate(goals, 1):
        client.send_goal(MoveBaseGoal(target_pose=pose_stamped(*goal)))
        if args.step:
            deadline = time.monotonic() + 30.0
            while client.get_state() == PENDING and time.monotonic() < deadline:
                time.sleep(0.01)  # wall time: the paused robot takes the goal now
            clock.run(args.timeout, "move_base")
            client.wait_for_result(rospy.Duration(0))  # done already: its result comes
            deadline = time.monotonic() + 30.0
            while client.get_result() is None and time.monotonic() < deadline:
                time.sleep(0.01)
        else:
            client.wait_for_result(rospy.Duration(args.timeout))
        state = client.get_state()
        results.append({"goal": goal, "state": state, "text": client.get_goal_status_text(),
                        "estimate": estimate[0]})
        print(f"goal {i}/{len(goals)} {goal}: {'SUCCEEDED' if state == SUCCEEDED else state} "
              f"{client.get_goal_status_text()}", flush=True)
    task = None
    if args.mark:
        exec_task = rospy.ServiceProxy("exec_task", ExecTask)
        res = exec_task(task_exect=1, task_id=1, task_type=4, direction=2, mark_no=args.mark)
        task = {"accepted": res.success, "message": res.message}
        if res.success:
            clock.run(600.0, "task")
            if not args.step:
                end = rospy.Time.now() + rospy.Duration(600.0)
                while not rospy.is_shutdown() and rospy.Time.now() < end:
                    with lock:
                        if statuses and statuses[-1]["task_state"] in (COMPLETED, CANCELLED,
                                                                       FAILED):
                            break
                    rospy.sleep(0.5)
    time.sleep(1.0)  # wall time: the last robot_status messages arrive
    with lock:
        final = statuses[-1]["task_state"] if statuses else None
    if task is not None:
        task["final_task_state"] = final
        print(f"transport task to {args.mark}: {task}", flush=True)
    ok = all(r["state"] == SUCCEEDED for r in results) and (task is None or
                                                           final == COMPLETED)
    if args.report:
        with open(args.report, "w", encoding="utf-8") as f:
            json.dump({"goals": results, "task": task, "robot_status": statuses,
                       "estimate": estimate[0],
                       "sim_time": [t_start, rospy.get_time()],
                       "wall_time": [wall_start, time.monotonic()]}, f, indent=1)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
