"""Run in the ROS 2 venv: an rclpy client of ``lowerbase driver --ros2``; prints one JSON line.

``odom N``        N /odom messages (after the first): their stamps' rate, frames, the count
``latched``       a late subscriber's ~link_state, /driver_base/parameter and /information
``service NAME``  once ~link_state is ready, calls the Trigger service NAME
``params``        the node's ROS 2 parameters topics.odom, command_rate, publish_tf
``drive``         once ~link_state is ready: /base_cmd_vel forward until /odom moved 0.2 m
``tf``            one odom -> base_link on /tf
``rosout``        NaN twists on /base_cmd_vel until driver_base's warning is on /rosout
``imu``           one /imu/data_raw (sensor-data QoS)
``rates``         /imu/data_raw's and /battery's rates by their stamps; the last battery
``static_pub``    publishes two static transforms through Ros2Wire, then waits to be killed
``static_sub``    a late subscriber's /tf_static
``clock_pub T``   publishes /clock from T s on at the wall clock's pace until killed

Every wait has a deadline (``TIMEOUT``) and fails in one line when it passes.
"""

from __future__ import annotations

import json
import sys
import time
from functools import partial
from itertools import pairwise
from typing import Any

import probe_common  # beside this script (sys.path[0])
import rclpy
from geometry_msgs.msg import TransformStamped, Twist
from nav_msgs.msg import Odometry
from probe_common import sec
from rcl_interfaces.srv import GetParameters
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu
from std_msgs.msg import String
from std_srvs.srv import Trigger
from tf2_msgs.msg import TFMessage
from woosh_msgs.msg import Information, Parameter

from lowerbase.ros2.wire import Ros2Wire, qos_for

TIMEOUT = 120.0
spin_until = partial(probe_common.spin_until, timeout=TIMEOUT)  # every wait's deadline
call = partial(probe_common.call, timeout=TIMEOUT)


def odom(node: Node, n: int) -> dict[str, Any]:
    got: list[Odometry] = []
    node.create_subscription(Odometry, "/odom", got.append, qos_for("/odom", 200))
    spin_until(node, lambda: len(got) > n, f"{n + 1} /odom messages")
    stamps = [sec(m.header.stamp) for m in got[: n + 1]]
    return {"count": n, "rate": n / (stamps[-1] - stamps[0]), "first": stamps[0],
            "frame_id": got[0].header.frame_id, "child_frame_id": got[0].child_frame_id,
            "backwards": sum(b < a for a, b in pairwise(stamps))}


def latched(node: Node) -> dict[str, Any]:
    state: list[String] = []
    param: list[Parameter] = []
    info: list[Information] = []
    node.create_subscription(String, "/driver_base/link_state", state.append,
                             qos_for("", latch=True))
    node.create_subscription(Parameter, "/driver_base/parameter", param.append,
                             qos_for("", latch=True))
    node.create_subscription(Information, "/information", info.append,
                             qos_for("", latch=True))
    spin_until(node, lambda: bool(state and param and info), "the latched topics")
    return {"link_state": state[-1].data, "wheelPerimeter": param[-1].wheelPerimeter,
            "pulsePerCircle": param[-1].pulsePerCircle,
            "hardwareVersion": info[-1].hardwareVersion}


def wait_ready(node: Node) -> None:
    state: list[str] = []
    node.create_subscription(String, "/driver_base/link_state", lambda m: state.append(m.data),
                             qos_for("", latch=True))
    spin_until(node, lambda: bool(state) and state[-1] == "ready", "~link_state ready")


def service(node: Node, name: str) -> dict[str, Any]:
    wait_ready(node)  # the command goes out only on a link that is up
    response = call(node, Trigger, name, Trigger.Request())
    return {"success": response.success, "message": response.message}


def params(node: Node) -> dict[str, Any]:
    names = ["topics.odom", "command_rate", "publish_tf"]
    response = call(node, GetParameters, "/driver_base/get_parameters",
                    GetParameters.Request(names=names))
    values = response.values
    return {"topics.odom": values[0].string_value, "command_rate": values[1].double_value,
            "publish_tf": values[2].bool_value}


def drive(node: Node) -> dict[str, Any]:
    wait_ready(node)
    return probe_common.drive(node, TIMEOUT)


def rosout(node: Node) -> dict[str, Any]:
    """Twists with NaN on /base_cmd_vel until driver_base's warning about them is on /rosout
    (transient local, as rcl publishes it: a line logged before the match still comes)."""
    from rcl_interfaces.msg import Log
    from rclpy.qos import DurabilityPolicy, QoSProfile

    logs: list[Log] = []
    node.create_subscription(Log, "/rosout", logs.append, QoSProfile(
        depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    wait_ready(node)
    pub = node.create_publisher(Twist, "/base_cmd_vel", qos_for("/base_cmd_vel"))
    bad = Twist()
    bad.linear.x = float("nan")

    def warned() -> bool:
        pub.publish(bad)
        return any("NaN or infinity" in m.msg for m in logs)

    spin_until(node, warned, "driver_base's warning on /rosout")
    m = next(m for m in logs if "NaN or infinity" in m.msg)
    return {"level": int(m.level), "name": m.name, "msg": m.msg}


def tf(node: Node) -> dict[str, Any]:
    got: list[TFMessage] = []
    node.create_subscription(TFMessage, "/tf", got.append, qos_for("/tf", 100))
    spin_until(node, lambda: bool(got), "/tf")
    t = got[-1].transforms[0]
    return {"frame_id": t.header.frame_id, "child_frame_id": t.child_frame_id}


def imu(node: Node) -> dict[str, Any]:
    got: list[Imu] = []
    node.create_subscription(Imu, "/imu/data_raw", got.append, qos_profile_sensor_data)
    spin_until(node, lambda: bool(got), "/imu/data_raw")
    return {"frame_id": got[-1].header.frame_id,
            "orientation_covariance0": got[-1].orientation_covariance[0],
            "accel_z": got[-1].linear_acceleration.z}


def rates(node: Node) -> dict[str, Any]:
    """/imu/data_raw (sensor-data QoS) and /battery: their rates by their stamps over ~5 s (501
    and 6 messages; /imu's by its publication sequence numbers, since a busy probe drops best
    effort samples), and the last battery; with the times driver_base said on /rosout that
    the lower computer fell behind real time (its Overruns moved) while they came: on a busy
    host the emulator's time may slip, and then fewer samples come per second, said."""
    from rcl_interfaces.msg import Log
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from woosh_msgs.msg import Battery

    imu: list[Imu] = []
    imu_seq: list[int] = []  #: publication sequence numbers: best effort may drop some here
    battery: list[Battery] = []
    logs: list[Log] = []

    def on_imu(msg: Imu, info: Any) -> None:
        imu.append(msg)
        imu_seq.append(int(info["publication_sequence_number"]))

    node.create_subscription(Imu, "/imu/data_raw", on_imu, qos_profile_sensor_data)
    node.create_subscription(Battery, "/battery", battery.append, qos_for("/battery", 10))
    node.create_subscription(Log, "/rosout", logs.append, QoSProfile(
        depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    spin_until(node, lambda: len(imu) > 500 and len(battery) > 5, "/imu/data_raw and /battery")

    def stamps(msgs: list[Any], n: int) -> list[float]:
        return [sec(m.header.stamp) for m in msgs[: n + 1]]

    def rate(msgs: list[Any], n: int, seq: list[int] | None = None) -> float:
        s = stamps(msgs, n)
        sent = n if seq is None else seq[n] - seq[0]  # published, whether all came or not
        return sent / (s[-1] - s[0])

    first = min(stamps(imu, 500)[0], stamps(battery, 5)[0])
    last_at = max(stamps(imu, 500)[-1], stamps(battery, 5)[-1])
    for _ in range(20):  # a slip is said with the next Heartbeat (every 0.5 s): until then
        rclpy.spin_once(node, timeout_sec=0.1)
    slips = [m.msg for m in logs if "fell behind real time" in m.msg
             and first <= sec(m.stamp) <= last_at + 1.0]
    last = battery[-1]
    return {"imu": rate(imu, 500, imu_seq), "battery": rate(battery, 5), "slips": slips,
            "imu_dropped_here": imu_seq[500] - imu_seq[0] - 500,
            "percentage": last.batteryPercentage, "voltage": last.batteryVoltage}


def static_pub(node: Node) -> None:
    broadcaster = Ros2Wire(node).static_broadcaster()
    for child, x in (("laser", 0.2), ("camera", 0.3)):
        t = TransformStamped()
        t.header.frame_id = "base_link"
        t.child_frame_id = child
        t.transform.translation.x = x
        t.transform.rotation.w = 1.0
        broadcaster.sendTransform(t)
    print("published", flush=True)
    while rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.5)


def clock_pub(node: Node, start: float) -> None:
    """/clock from ``start`` [s] on, at the wall clock's pace, every 10 ms until killed."""
    pub = node.create_publisher(Clock, "/clock", 10)
    t0 = time.monotonic()
    print("publishing", flush=True)
    while rclpy.ok():
        now = start + time.monotonic() - t0
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = int(now), int((now % 1.0) * 1e9)
        pub.publish(msg)
        rclpy.spin_once(node, timeout_sec=0.01)


def static_sub(node: Node) -> dict[str, Any]:
    got: list[TFMessage] = []
    node.create_subscription(TFMessage, "/tf_static", got.append,
                             qos_for("/tf_static", latch=True))
    spin_until(node, lambda: bool(got), "/tf_static")
    return {t.child_frame_id: t.transform.translation.x for t in got[-1].transforms}


def main() -> None:
    mode, args = sys.argv[1], sys.argv[2:]
    rclpy.init()
    node = rclpy.create_node(f"lowerbase_probe_{mode}")
    if mode == "static_pub":
        static_pub(node)
        return
    if mode == "clock_pub":
        clock_pub(node, float(args[0]))
        return
    result: Any
    if mode == "odom":
        result = odom(node, int(args[0]))
    elif mode == "service":
        result = service(node, args[0])
    else:
        result = {"latched": latched, "params": params, "drive": drive, "tf": tf, "imu": imu,
                  "static_sub": static_sub, "rosout": rosout, "rates": rates}[mode](node)
    print(json.dumps(result), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
