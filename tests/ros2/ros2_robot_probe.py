"""Run in the ROS 2 venv: an rclpy client of ``lowerbase robot --ros2 --sim-time``; prints one
JSON line.

``topics``           /odom (20 messages), one /scan (sensor-data QoS), /clock advancing
``latched``          a late subscriber's /map and /tf_static
``tf``               map -> odom and odom -> base_link on /tf, base_link -> laser on /tf_static
``navigate X Y YAW`` a NavigateToPose goal: its feedback, its end, the robot's map pose after
``move_base X Y YAW`` the same through the vendor's /move_base (woosh_msgs/action/MoveBase)
``steps D``          one straight step of D m through /cmd_vel_control
``drive``            a Twist on /base_cmd_vel from outside until /odom moved 0.2 m
``preempt``          a navigate_to_pose goal cancelled, another preempted by /move_base
``services X Y``     /move_base/make_plan to (X, Y) from the robot; clear_costmaps
``plan X Y``         compute_path_to_pose to (X, Y) from the robot; the robot's map pose
``task ID DIR``      exec_task: transport to R1 (direction DIR); robot_status to its end
``param NAME``       the robot node's ROS 2 parameter NAME (its GetParameters service)
``navigation_mode``  a /navigation_mode goal the navigator takes, then one it refuses
``camera``           one depth camera_info and one depth image (robot --camera)

Every wait has a deadline (``TIMEOUT``) and fails in one line when it passes.
"""

from __future__ import annotations

import json
import math
import sys
from functools import partial
from itertools import pairwise
from typing import Any

import probe_common  # beside this script (sys.path[0])
import rclpy
from nav2_msgs.action import ComputePathToPose, NavigateToPose
from nav_msgs.msg import OccupancyGrid, Odometry
from probe_common import sec
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

from lowerbase.ros2.wire import clock_qos, qos_for

TIMEOUT = 180.0
spin_until = partial(probe_common.spin_until, timeout=TIMEOUT)  # every wait's deadline


def yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def topics(node: Node) -> dict[str, Any]:
    odom: list[Odometry] = []
    scans: list[LaserScan] = []
    clock: list[float] = []
    node.create_subscription(Odometry, "/odom", odom.append, qos_for("/odom", 100))
    node.create_subscription(LaserScan, "/scan", scans.append, qos_profile_sensor_data)
    node.create_subscription(Clock, "/clock", lambda m: clock.append(sec(m.clock)), clock_qos())
    spin_until(node, lambda: len(odom) > 20 and bool(scans) and len(clock) > 10,
               "/odom, /scan and /clock")
    stamps = [sec(m.header.stamp) for m in odom[:21]]
    return {"odom_rate": 20 / (stamps[-1] - stamps[0]), "odom_frame": odom[0].header.frame_id,
            "odom_child": odom[0].child_frame_id, "scan_frame": scans[0].header.frame_id,
            "scan_beams": len(scans[0].ranges), "clock_first": clock[0],
            "clock_last": clock[-1], "clock_backwards": sum(b < a for a, b in
                                                            pairwise(clock))}


def latched(node: Node) -> dict[str, Any]:
    maps: list[OccupancyGrid] = []
    static: list[TFMessage] = []
    node.create_subscription(OccupancyGrid, "/map", maps.append, qos_for("/map", latch=True))
    node.create_subscription(TFMessage, "/tf_static", static.append,
                             qos_for("/tf_static", latch=True))
    spin_until(node, lambda: bool(maps and static), "/map and /tf_static")
    m = maps[-1]
    return {"map_frame": m.header.frame_id, "width": m.info.width, "height": m.info.height,
            "resolution": round(m.info.resolution, 6), "cells": len(m.data),
            "static": sorted(f"{t.header.frame_id}->{t.child_frame_id}"
                             for msg in static for t in msg.transforms)}


class Tf:
    """The newest transform of each parent -> child pair on /tf and /tf_static."""

    def __init__(self, node: Node) -> None:
        self.edges: dict[tuple[str, str], Any] = {}
        node.create_subscription(TFMessage, "/tf", self._on, qos_for("/tf", 100))
        node.create_subscription(TFMessage, "/tf_static", self._on,
                                 qos_for("/tf_static", latch=True))

    def _on(self, msg: TFMessage) -> None:
        for t in msg.transforms:
            self.edges[(t.header.frame_id, t.child_frame_id)] = t

    def has(self, *pairs: tuple[str, str]) -> bool:
        return all(p in self.edges for p in pairs)

    def pose(self, parent: str, child: str) -> tuple[float, float, float]:
        t = self.edges[(parent, child)].transform
        return t.translation.x, t.translation.y, yaw(t.rotation)

    def map_pose(self) -> tuple[float, float, float]:
        """The robot in the map frame: map -> odom composed with odom -> base_link."""
        mx, my, mt = self.pose("map", "odom")
        ox, oy, ot = self.pose("odom", "base_link")
        return (mx + ox * math.cos(mt) - oy * math.sin(mt),
                my + ox * math.sin(mt) + oy * math.cos(mt), mt + ot)


def tf(node: Node) -> dict[str, Any]:
    buf = Tf(node)
    spin_until(node, lambda: buf.has(("map", "odom"), ("odom", "base_link")) and any(
        p == "base_link" for p, _ in buf.edges), "map -> odom -> base_link -> laser")
    return {"edges": sorted(f"{p}->{c}" for p, c in buf.edges),
            "map_pose": buf.map_pose()}


def goal_end(node: Node, client: ActionClient, goal: Any, name: str,
             feedback: list[Any] | None = None) -> Any:
    """Send ``goal`` to the action server ``name``; exit in one line if it refuses it; its
    end (status, result). Feedback is appended to ``feedback``."""
    callback = None if feedback is None else (lambda m: feedback.append(m.feedback))
    sent = client.send_goal_async(goal, feedback_callback=callback)
    spin_until(node, sent.done, "the goal's acceptance")
    handle = sent.result()
    if not handle.accepted:
        sys.exit(f"probe: {name} refused the goal")
    result = handle.get_result_async()
    spin_until(node, result.done, f"the {name} result")
    return result.result()


def navigate(node: Node, x: float, y: float, th: float) -> dict[str, Any]:
    buf = Tf(node)
    client = ActionClient(node, NavigateToPose, "/navigate_to_pose")
    spin_until(node, lambda: client.server_is_ready(), "the navigate_to_pose server")
    feedback: list[Any] = []
    goal = NavigateToPose.Goal()
    goal.pose.header.frame_id = "map"
    goal.pose.pose.position.x, goal.pose.pose.position.y = x, y
    goal.pose.pose.orientation.z, goal.pose.pose.orientation.w = math.sin(th / 2), \
        math.cos(th / 2)
    end = goal_end(node, client, goal, "navigate_to_pose", feedback)
    spin_until(node, lambda: buf.has(("map", "odom"), ("odom", "base_link")), "TF")
    first, last = feedback[0], feedback[-1]
    return {"status": end.status, "error_code": end.result.error_code,
            "error_msg": end.result.error_msg, "feedback": len(feedback),
            "first_distance": first.distance_remaining, "last_distance":
            last.distance_remaining, "first_time": sec(first.navigation_time),
            "last_time": sec(last.navigation_time),
            "frame": last.current_pose.header.frame_id,
            "first_pose": (first.current_pose.pose.position.x,
                           first.current_pose.pose.position.y),
            "last_pose": (last.current_pose.pose.position.x, last.current_pose.pose.position.y),
            "map_pose": buf.map_pose()}


def move_base(node: Node, x: float, y: float, th: float) -> dict[str, Any]:
    """The vendor's /move_base (woosh_msgs/action/MoveBase): feedback and the end."""
    from woosh_msgs.action import MoveBase

    buf = Tf(node)
    client = ActionClient(node, MoveBase, "/move_base")
    spin_until(node, lambda: client.server_is_ready(), "the move_base server")
    feedback: list[Any] = []
    goal = MoveBase.Goal(execution_mode=0)
    goal.target_pose.header.frame_id = "map"
    goal.target_pose.pose.position.x, goal.target_pose.pose.position.y = x, y
    goal.target_pose.pose.orientation.z = math.sin(th / 2)
    goal.target_pose.pose.orientation.w = math.cos(th / 2)
    end = goal_end(node, client, goal, "move_base", feedback)
    spin_until(node, lambda: buf.has(("map", "odom"), ("odom", "base_link")), "TF")
    last = feedback[-1].base_position
    return {"status": end.status, "feedback": len(feedback),
            "frame": last.header.frame_id,
            "last_pose": (last.pose.position.x, last.pose.position.y),
            "map_pose": buf.map_pose()}


def navigation_mode(node: Node) -> dict[str, Any]:
    """/navigation_mode (woosh_msgs/action/NavigationMode): precise avoidance at 0.4 m/s, then
    an unknown mode (9): each goal's end (status, result)."""
    from woosh_msgs.action import NavigationMode

    client = ActionClient(node, NavigationMode, "/navigation_mode")
    spin_until(node, lambda: client.server_is_ready(), "the navigation_mode server")
    good = goal_end(node, client, NavigationMode.Goal(navigation_mode=1, max_speed=0.4),
                    "navigation_mode")
    bad = goal_end(node, client, NavigationMode.Goal(navigation_mode=9, max_speed=0.4),
                   "navigation_mode")
    return {"good": [good.status, good.result.result], "bad": [bad.status, bad.result.result]}


def camera(node: Node) -> dict[str, Any]:
    """One /camera_1/depth/camera_info and one /camera_1/depth/image_raw (sensor-data QoS,
    which takes reliable publishers too)."""
    from sensor_msgs.msg import CameraInfo, Image

    infos: list[CameraInfo] = []
    images: list[Image] = []
    node.create_subscription(CameraInfo, "/camera_1/depth/camera_info", infos.append,
                             qos_profile_sensor_data)
    node.create_subscription(Image, "/camera_1/depth/image_raw", images.append,
                             qos_profile_sensor_data)
    spin_until(node, lambda: bool(infos) and bool(images), "the depth camera's topics")
    info, image = infos[0], images[0]
    return {"info": [info.width, info.height, info.distortion_model, list(info.d),
                     list(info.k), list(info.p)],
            "image": [image.width, image.height, image.encoding, len(image.data)],
            "frame": info.header.frame_id}


def drive(node: Node) -> dict[str, Any]:
    """A Twist on /base_cmd_vel from this process until /odom moved 0.2 m (probe_common)."""
    return probe_common.drive(node, TIMEOUT)


def _pose_goal(cls: Any, field: str, x: float, y: float) -> Any:
    goal = cls.Goal()
    pose = getattr(goal, field)
    pose.header.frame_id = "map"
    pose.pose.position.x, pose.pose.position.y = x, y
    pose.pose.orientation.w = 1.0
    return goal


def preempt(node: Node) -> dict[str, Any]:
    """How navigate_to_pose goals end on ROS 2: one cancelled by its client, one preempted by
    a /move_base goal (that one's end too)."""
    from woosh_msgs.action import MoveBase

    nav = ActionClient(node, NavigateToPose, "/navigate_to_pose")
    vendor = ActionClient(node, MoveBase, "/move_base")
    spin_until(node, lambda: nav.server_is_ready() and vendor.server_is_ready(), "the servers")

    def send(client: ActionClient, goal: Any, feedback: list[Any]) -> Any:
        sent = client.send_goal_async(goal, feedback_callback=feedback.append)
        spin_until(node, sent.done, "the goal's acceptance")
        return sent.result()

    seen: list[Any] = []
    handle = send(nav, _pose_goal(NavigateToPose, "pose", 2.0, 2.0), seen)
    spin_until(node, lambda: len(seen) >= 3, "feedback")
    cancel = handle.cancel_goal_async()
    spin_until(node, cancel.done, "the cancel answer")
    cancelled = handle.get_result_async()
    spin_until(node, cancelled.done, "the cancelled goal's end")
    seen = []
    handle = send(nav, _pose_goal(NavigateToPose, "pose", 2.0, 6.0), seen)
    spin_until(node, lambda: len(seen) >= 3, "feedback")
    other = send(vendor, _pose_goal(MoveBase, "target_pose", 4.0, 4.0), [])
    preempted = handle.get_result_async()
    spin_until(node, preempted.done, "the preempted goal's end")
    won = other.get_result_async()
    spin_until(node, won.done, "the move_base goal's end")
    return {"cancel_answer": len(cancel.result().goals_canceling),
            "cancelled": cancelled.result().status,
            "preempted": preempted.result().status,
            "preempted_error": preempted.result().result.error_code,
            "preempted_msg": preempted.result().result.error_msg,
            "move_base": won.result().status}


def steps(node: Node, distance: float) -> dict[str, Any]:
    """/cmd_vel_control (woosh_msgs/action/StepControl): one straight step of
    ``distance`` m; /odom's pose before and after."""
    from woosh_msgs.action import StepControl as StepAction
    from woosh_msgs.msg import StepControl

    odom: list[Odometry] = []
    node.create_subscription(Odometry, "/odom", odom.append, qos_for("/odom", 50))
    client = ActionClient(node, StepAction, "/cmd_vel_control")
    spin_until(node, lambda: client.server_is_ready() and bool(odom), "the server and /odom")
    before = odom[-1].pose.pose.position
    x0, y0 = before.x, before.y
    feedback: list[Any] = []
    goal = StepAction.Goal(mode=1, useAvoid=False, stepControl=[
        StepControl(executeMode=1, data=distance, speed=0.0, angle=0.0)])
    end = goal_end(node, client, goal, "cmd_vel_control", feedback)
    n = len(odom)
    spin_until(node, lambda: len(odom) > n + 50, "/odom after the end")  # 1 s: standing
    after = odom[-1].pose.pose.position
    return {"status": end.status, "result": end.result.result,
            "executeMode": end.result.executeMode, "percent": end.result.percent,
            "feedback": len(feedback), "moved": math.hypot(after.x - x0, after.y - y0)}


def plan(node: Node, x: float, y: float) -> dict[str, Any]:
    buf = Tf(node)
    client = ActionClient(node, ComputePathToPose, "/compute_path_to_pose")
    spin_until(node, lambda: client.server_is_ready() and buf.has(
        ("map", "odom"), ("odom", "base_link")), "the compute_path_to_pose server and TF")
    goal = ComputePathToPose.Goal(use_start=False)
    goal.goal.header.frame_id = "map"
    goal.goal.pose.position.x, goal.goal.pose.position.y = x, y
    goal.goal.pose.orientation.w = 1.0
    end = goal_end(node, client, goal, "compute_path_to_pose")
    poses = [(p.pose.position.x, p.pose.position.y) for p in end.result.path.poses]
    return {"status": end.status, "error_code": end.result.error_code, "n": len(poses),
            "frame": end.result.path.header.frame_id, "first": poses[0] if poses else None,
            "last": poses[-1] if poses else None, "map_pose": buf.map_pose()}


def task(node: Node, task_id: int, direction: int) -> dict[str, Any]:
    """A transporting task (type 4) to R1 through exec_task, as examples/transport_task.py;
    robot_status until the task ends; the robot's map pose then."""
    from woosh_msgs.msg import RobotStatus
    from woosh_msgs.srv import ExecTask

    buf = Tf(node)
    statuses: list[Any] = []
    node.create_subscription(RobotStatus, "/robot_status", statuses.append,
                             qos_for("/robot_status", latch=True))
    client = node.create_client(ExecTask, "/exec_task")
    spin_until(node, lambda: client.service_is_ready() and bool(statuses)
               and statuses[-1].robot_state != 1, "exec_task and an initialized robot")
    call = client.call_async(ExecTask.Request(task_exect=1, task_id=task_id, task_type=4,
                                              direction=direction, mark_no="R1"))
    spin_until(node, call.done, "the exec_task answer")
    answer = call.result()
    if answer.success:
        spin_until(node, lambda: statuses[-1].task_id == task_id
                   and statuses[-1].task_state in (7, 8, 9), "the task's end", timeout=600)
    spin_until(node, lambda: buf.has(("map", "odom"), ("odom", "base_link")), "TF")
    last = statuses[-1]
    return {"success": answer.success, "message": answer.message,
            "task_state": last.task_state, "dest": last.dest, "statuses": len(statuses),
            "task_states": sorted({s.task_state for s in statuses if s.task_id == task_id}),
            "map_pose": buf.map_pose()}


def services(node: Node, x: float, y: float) -> dict[str, Any]:
    """/move_base/make_plan (nav_msgs/GetPlan, start empty: the robot) and
    /move_base/clear_costmaps (std_srvs/Empty)."""
    from nav_msgs.srv import GetPlan
    from std_srvs.srv import Empty

    make_plan = node.create_client(GetPlan, "/move_base/make_plan")
    clear = node.create_client(Empty, "/move_base/clear_costmaps")
    spin_until(node, lambda: make_plan.service_is_ready() and clear.service_is_ready(),
               "the services")
    request = GetPlan.Request(tolerance=0.0)
    request.goal.header.frame_id = "map"
    request.goal.pose.position.x, request.goal.pose.position.y = x, y
    request.goal.pose.orientation.w = 1.0
    call = make_plan.call_async(request)
    spin_until(node, call.done, "make_plan's answer")
    poses = [(p.pose.position.x, p.pose.position.y) for p in call.result().plan.poses]
    cleared = clear.call_async(Empty.Request())
    spin_until(node, cleared.done, "clear_costmaps' answer")
    return {"n": len(poses), "last": poses[-1] if poses else None,
            "cleared": isinstance(cleared.result(), Empty.Response)}


def parameter(node: Node, name: str) -> dict[str, Any]:
    """``ros2 param get /lowerbase_robot NAME``: the robot node's parameter service."""
    from rcl_interfaces.srv import GetParameters

    client = node.create_client(GetParameters, "/lowerbase_robot/get_parameters")
    spin_until(node, lambda: client.service_is_ready(), "/lowerbase_robot/get_parameters")
    future = client.call_async(GetParameters.Request(names=[name]))
    spin_until(node, future.done, "the parameter's answer")
    [value] = future.result().values
    return {"type": value.type, "strings": list(value.string_array_value)}


def main() -> None:
    if sys.argv[1] == "param":
        rclpy.init()
        node = rclpy.create_node("lowerbase_probe_param")
        print(json.dumps(parameter(node, sys.argv[2])), flush=True)
        node.destroy_node()
        rclpy.shutdown()
        return
    mode, args = sys.argv[1], [float(a) for a in sys.argv[2:]]
    rclpy.init()
    node = rclpy.create_node(f"lowerbase_probe_{mode}")
    result: Any
    if mode == "navigate":
        result = navigate(node, *args)
    elif mode == "move_base":
        result = move_base(node, *args)
    elif mode == "plan":
        result = plan(node, *args)
    elif mode == "steps":
        result = steps(node, *args)
    elif mode == "services":
        result = services(node, *args)
    elif mode == "task":
        result = task(node, int(args[0]), int(args[1]))
    else:
        result = {"topics": topics, "latched": latched, "tf": tf, "drive": drive,
                  "preempt": preempt, "navigation_mode": navigation_mode,
                  "camera": camera}[mode](node)
    print(json.dumps(result), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
