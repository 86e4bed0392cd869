"""Run in the ROS 2 venv: an rclpy client of ``lowerbase robot --robot legged --sim-time
--ros2``; prints one JSON line.

``interface``        the robot's topics and services (names, types) and robot_state's QoS
``topics``           robot_state per second of /clock's time (each message's publication
                     time, read from its source timestamp), /clock
``services DIR``     planning/*, set_listen and set_map (its PCD file goes to DIR)
``walk``             ~walk until IN_CONTROL, /cmd_vel until the base moved 0.3 m, ~stand

Every wait has a deadline (``TIMEOUT``) and fails in one line when it passes.
"""

from __future__ import annotations

import json
import math
import struct
import sys
from bisect import bisect_right
from functools import partial
from itertools import pairwise
from typing import Any

import probe_common  # beside this script (sys.path[0])
import rclpy
from geometry_msgs.msg import Twist
from lowerbase_legged_msgs.msg import RobotState, Waypoint
from lowerbase_legged_msgs.srv import GetWaypoints, SetLaserMap, SetListen, SetWaypoints
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2, PointField
from std_srvs.srv import Trigger

from lowerbase.ros2.wire import qos_for

TIMEOUT = 180.0
spin_until = partial(probe_common.spin_until, timeout=TIMEOUT)  # every wait's deadline
call = partial(probe_common.call, timeout=TIMEOUT)
ROBOT = "/lowerbase_robot"
STATE_PERIOD = 0.02  #: [s] robot_state's period (~publish_rate 50 Hz)
TOPICS = {"/robot_state": "lowerbase_legged_msgs/msg/RobotState",
          "/clock": "rosgraph_msgs/msg/Clock"}
SUBSCRIBED = {"/cmd_vel": "geometry_msgs/msg/Twist"}
SERVICES = {"/planning/set_waypoints": "lowerbase_legged_msgs/srv/SetWaypoints",
            "/planning/get_waypoints": "lowerbase_legged_msgs/srv/GetWaypoints",
            "/planning/append_waypoint": "lowerbase_legged_msgs/srv/AppendWaypoint",
            "/set_map": "lowerbase_legged_msgs/srv/SetLaserMap",
            "/set_listen": "lowerbase_legged_msgs/srv/SetListen",
            **{f"/legged_driver/{n}": "std_srvs/srv/Trigger"
               for n in ("walk", "stand", "sit", "stop_waypoints")}}


class States:
    """robot_state as it comes, with its publication sequence numbers (gaps: lost ones) and
    source timestamps (the robot's wall clock when it published each)."""

    def __init__(self, node: Node) -> None:
        self.msgs: list[RobotState] = []
        self.seqs: list[int] = []
        self.sent: list[int] = []  #: [ns] source timestamps
        self.node = node
        node.create_subscription(RobotState, "/robot_state", self._on,
                                 qos_for("/robot_state", 1000))

    def _on(self, msg: RobotState, info: Any) -> None:
        self.msgs.append(msg)
        self.seqs.append(int(info["publication_sequence_number"]))
        self.sent.append(int(info["source_timestamp"]))

    def wait(self, done: Any, what: str) -> RobotState:
        spin_until(self.node, lambda: bool(self.msgs) and done(self.msgs[-1]), what)
        return self.msgs[-1]


def interface(node: Node) -> dict[str, Any]:
    def robots(infos: Any) -> list[Any]:
        return [i for i in infos if i.node_name == ROBOT[1:]]

    def seen() -> bool:
        topics = dict(node.get_topic_names_and_types())
        services = dict(node.get_service_names_and_types())
        return all(n in topics for n in (*TOPICS, *SUBSCRIBED)) and \
            all(n in services for n in SERVICES) and \
            bool(robots(node.get_publishers_info_by_topic("/robot_state"))) and \
            bool(robots(node.get_subscriptions_info_by_topic("/cmd_vel")))

    spin_until(node, seen, "the robot's topics and services")
    topics = dict(node.get_topic_names_and_types())
    services = dict(node.get_service_names_and_types())
    [state_pub] = robots(node.get_publishers_info_by_topic("/robot_state"))
    subscribers = {i.node_name for i in node.get_subscriptions_info_by_topic("/cmd_vel")}
    return {"topics": {n: topics[n] for n in (*TOPICS, *SUBSCRIBED)},
            "services": {n: services[n] for n in SERVICES},
            "cmd_vel_subscribers": sorted(subscribers),
            "state_qos": [state_pub.qos_profile.reliability.name,
                          state_pub.qos_profile.durability.name]}


def topics(node: Node) -> dict[str, Any]:
    """robot_state's rate in /clock's time. The robot publishes /clock and robot_state from
    one thread, so each robot_state was sent at the simulated time of the last /clock sent
    before it (source timestamps, the robot's wall clock): a rate that holds however late this
    process takes them (on a busy host it takes several of each topic in a burst, so its own
    ROS time at each message says nothing). Ends are states between two /clock messages 10 ms
    apart (none lost between them)."""
    states = States(node)
    clocks: list[tuple[int, float]] = []  #: (source timestamp [ns], /clock [s])
    node.create_subscription(
        Clock, "/clock", lambda m, i: clocks.append((int(i["source_timestamp"]),
                                                     probe_common.sec(m.clock))),
        QoSProfile(depth=2000, reliability=ReliabilityPolicy.BEST_EFFORT))
    spin_until(node, lambda: len(states.msgs) >= 300 and len(clocks) > 10,
               "300 robot_state and /clock")
    sent = [t for t, _ in clocks]
    pinned = []  #: (sequence number, simulated time of sending) of the states with a bracket
    for seq, at in zip(states.seqs, states.sent, strict=True):
        k = bisect_right(sent, at)
        if 0 < k < len(clocks) and clocks[k][1] - clocks[k - 1][1] < 0.015:
            pinned.append((seq, clocks[k - 1][1]))
    (seq0, t0), (seq1, t1) = pinned[0], pinned[-1]
    return {"state_rate": (seq1 - seq0) / (t1 - t0), "span": t1 - t0, "pinned": len(pinned),
            "lost": sum(b - a - 1 for a, b in pairwise(states.seqs)),
            "actuators": len(states.msgs[-1].actuator_states),
            "state": states.msgs[-1].state, "clock_first": clocks[0][1],
            "clock_last": clocks[-1][1],
            "clock_backwards": sum(b[1] < a[1] for a, b in pairwise(clocks))}


def cloud(points: list[tuple[float, float, float]]) -> PointCloud2:
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, n in enumerate("xyz")]
    return PointCloud2(height=1, width=len(points), fields=fields, is_bigendian=False,
                       point_step=12, row_step=12 * len(points), is_dense=True,
                       data=b"".join(struct.pack("<3f", *p) for p in points))


def services(node: Node, map_dir: str) -> dict[str, Any]:
    states = States(node)
    listen0 = states.wait(lambda m: True, "robot_state").joy_listen_type
    empty = call(node, SetWaypoints, "/planning/set_waypoints", SetWaypoints.Request())
    appended = call(node, SetWaypoints, "/planning/set_waypoints", SetWaypoints.Request(
        waypoints=[Waypoint(frame="odom", x=5.0, y=0.0)], repetition=1))
    got = call(node, GetWaypoints, "/planning/get_waypoints", GetWaypoints.Request())
    stopped = call(node, Trigger, "/legged_driver/stop_waypoints", Trigger.Request())
    listen = call(node, SetListen, "/set_listen", SetListen.Request(data="joy<&>probe"))
    n = len(states.msgs)
    joy = states.wait(lambda m: len(states.msgs) > n and m.joy_listen_type == RobotState.JOY,
                      "joy_listen_type JOY").joy_listen_type
    closed = call(node, SetListen, "/set_listen", SetListen.Request(data="joy<&><CLOSE>"))
    n = len(states.msgs)
    back = states.wait(lambda m: len(states.msgs) > n and m.joy_listen_type == listen0,
                       "joy_listen_type back").joy_listen_type
    request = SetLaserMap.Request(name="probe_map", pc=cloud([(1.0, 2.0, 0.5), (3.0, -1.0, 0.25),
                                                              (0.0, 0.0, 0.0)]))
    request.initial_pose.orientation.w = 1.0
    mapped = call(node, SetLaserMap, "/set_map", request)
    return {"empty": [empty.success, empty.message], "set": [appended.success, appended.message],
            "get": [got.success, len(got.waypoints), got.repetition],
            "stopped": stopped.success, "listen": [listen.success, listen.message],
            "closed": closed.success, "joy": [listen0, joy, back],
            "map": [mapped.success, mapped.message], "map_dir": map_dir}


def walk(node: Node) -> dict[str, Any]:
    """~walk, then /cmd_vel at 0.3 m/s (one Twist per robot_state: 50 Hz of simulated time,
    whatever the speed) until the base moved 0.3 m, then zeros and ~stand."""
    states = States(node)
    states.wait(lambda m: True, "robot_state")
    answer = call(node, Trigger, "/legged_driver/walk", Trigger.Request())
    states.wait(lambda m: m.state == RobotState.IN_CONTROL, "IN_CONTROL")
    pub = node.create_publisher(Twist, "/cmd_vel", qos_for("/cmd_vel"))
    cmd = Twist()
    cmd.linear.x = 0.3
    first = len(states.msgs)
    x0, y0 = states.msgs[-1].base_pos[:2]

    def moved() -> float:
        p = states.msgs[-1].base_pos
        return math.hypot(p[0] - x0, p[1] - y0)

    answered = [first]  # robot_state answered with a Twist so far

    def drive() -> bool:
        for _ in range(answered[0], len(states.msgs)):
            pub.publish(cmd)
        answered[0] = len(states.msgs)
        return moved() >= 0.3

    spin_until(node, drive, "the base 0.3 m on")
    walked = states.msgs[first - 1:]
    seqs = states.seqs[first - 1:]
    for _ in range(3):
        pub.publish(Twist())
    stand = call(node, Trigger, "/legged_driver/stand", Trigger.Request())
    states.wait(lambda m: m.state == RobotState.STANDING_MODE, "STANDING_MODE")
    path = said = 0.0  # over consecutive robot_state only (a lost one is left out)
    for (a, sa), (b, sb) in pairwise(zip(walked, seqs, strict=True)):
        if sb == sa + 1:
            path += math.hypot(b.base_pos[0] - a.base_pos[0], b.base_pos[1] - a.base_pos[1])
            said += math.hypot(*a.base_lin_vel[:2]) * STATE_PERIOD
    last = walked[-1]
    return {"walk": [answer.success, answer.message], "stand": [stand.success, stand.message],
            "moved": moved(), "path": path, "said": said, "speed": float(last.base_lin_vel[0]),
            "heading_x": last.base_pos[0] - x0, "state": states.msgs[-1].state}


def main() -> None:
    mode, args = sys.argv[1], sys.argv[2:]
    rclpy.init()
    node = rclpy.create_node(f"lowerbase_legged_probe_{mode}", parameter_overrides=[
        Parameter("use_sim_time", Parameter.Type.BOOL, True)])
    result: Any
    if mode == "services":
        result = services(node, *args)
    else:
        result = {"interface": interface, "topics": topics, "walk": walk}[mode](node)
    print(json.dumps(result), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
