"""Run in the ROS 2 venv: an rclpy client of ``lowerbase robot --ros2 --paused``, moving its
time by ``/lowerbase/step`` (lowerbase_sim_msgs/srv/Step); prints one JSON line.

``step S``   the latched /lowerbase/sim_status; a step of S simulated seconds and the /odom
             stamps it brought (each once, none left out: the robot published them before the
             step returned, in order); a refused step (seconds <= 0); /lowerbase/pause false
             (time runs again) and a step refused while it runs

Every wait has a deadline (``TIMEOUT``) and fails in one line when it passes.
"""

from __future__ import annotations

import json
import sys
from functools import partial
from typing import Any

import probe_common  # beside this script (sys.path[0])
import rclpy
from lowerbase_sim_msgs.msg import SimStatus
from lowerbase_sim_msgs.srv import Step
from nav_msgs.msg import Odometry
from probe_common import sec
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_srvs.srv import SetBool

from lowerbase.ros2.wire import clock_qos, qos_for

TIMEOUT = 180.0
spin_until = partial(probe_common.spin_until, timeout=TIMEOUT)  # every wait's deadline
call = partial(probe_common.call, timeout=TIMEOUT)


def step(node: Node, seconds: float) -> dict[str, Any]:
    status: list[SimStatus] = []
    odom: list[float] = []
    clock: list[float] = []
    node.create_subscription(SimStatus, "/lowerbase/sim_status", status.append,
                             qos_for("/lowerbase/sim_status", latch=True))
    node.create_subscription(Odometry, "/odom", lambda m: odom.append(sec(m.header.stamp)),
                             qos_for("/odom", 1000))
    node.create_subscription(Clock, "/clock", lambda m: clock.append(sec(m.clock)), clock_qos())
    spin_until(node, lambda: bool(status), "/lowerbase/sim_status")
    first = status[-1]
    t0 = first.sim_time
    # the robot publishes /odom once it has matched this subscription (discovery takes wall
    # time, and no simulated time passes while paused): short steps until one comes
    warm = None
    while not odom:
        warm = call(node, Step, "/lowerbase/step", Step.Request(seconds=0.02))
        for _ in range(3):
            rclpy.spin_once(node, timeout_sec=0.1)
        if warm.sim_time > t0 + 60.0:
            sys.exit("probe: no /odom after 60 simulated s of steps")
    assert warm is not None
    t1 = warm.sim_time
    done = call(node, Step, "/lowerbase/step", Step.Request(seconds=seconds, until=""))
    t2 = done.sim_time
    # /odom comes in the order it was published: one stamped after t2 means every /odom
    # stamped up to t2 has come
    call(node, Step, "/lowerbase/step", Step.Request(seconds=0.1))
    spin_until(node, lambda: odom[-1] > t2 + 1e-3, "/odom after the step's end")
    # [s] stamps are whole nanoseconds of a simulated time summed period by period
    brought = [t for t in odom if t1 + 1e-6 < t <= t2 + 1e-6]
    refused = call(node, Step, "/lowerbase/step", Step.Request(seconds=-1.0))
    resumed = call(node, SetBool, "/lowerbase/pause", SetBool.Request(data=False))
    spin_until(node, lambda: bool(clock) and clock[-1] > t2 + 0.5, "/clock running again")
    spin_until(node, lambda: not status[-1].paused, "sim_status not paused")
    running = call(node, Step, "/lowerbase/step", Step.Request(seconds=1.0))
    return {"paused": first.paused, "start": t0, "warm": [warm.success, t1],
            "step": [done.success, done.message, t2 - t1, done.until_met],
            "odom": len(brought), "odom_distinct": len(set(brought)),
            "refused": [refused.success, refused.message],
            "resumed": [resumed.success, resumed.message],
            "running": [running.success, running.message]}


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("lowerbase_step_probe")
    result = step(node, float(sys.argv[2]))
    print(json.dumps(result), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
