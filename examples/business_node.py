#!/usr/bin/env python3
"""A business node of shared/seeds/001: drives `lowerbase trace` with the seed's messages only.

It publishes a GTraceList on msg_trace_navigate_route and answers as the seed's diagram says:
TraceNavigate's BLOCKED -> the list to ObstacleNavigate (msg_obstacle_navigate_route); its
FINISHED -> the list, with ``finished`` saying where to continue, back to TraceNavigate; its
FINISHED -> done. ``--cancel-after S`` sends the empty list S seconds (ROS time) after the first
RUNNING instead, and waits for IDLE. Every message is a protobuf message in a
lowerbase_msgs/Protobuf (``type``, ``data``); nothing else of lowerbase is used.

    .venv/bin/python examples/business_node.py --route 6,1.2:11,1.2:16,1.2:21,1.2 --map warehouse

Each report is printed as ``business: <topic> <STATUS> finished=<f0>,<f1>,...``; the exit code
is 0 when the route finished (or the cancel was answered with IDLE), 1 otherwise.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import threading
import time

import rospy
from lowerbase_msgs.msg import Protobuf

from lowerbase.trace.proto.trace_pb2 import GTraceList

ROUTE, STATUS = "msg_trace_navigate_route", "msg_trace_navigate_status"
AVOID_ROUTE, AVOID_STATUS = "msg_obstacle_navigate_route", "msg_obstacle_navigate_status"
NAMES = {v: k.removeprefix("EXECUTE_STATUS_") for k, v in GTraceList.ExecuteStatus.items()}


def route_list(text: str, map_name: str, speed: int) -> GTraceList:
    """A GTraceList through the points ``x,y:x,y:...``; its first point may start it."""
    try:
        points = [tuple(float(v) for v in p.split(",")) for p in text.split(":")]
    except ValueError:
        points = []
    if len(points) < 2 or any(len(p) != 2 for p in points):
        raise SystemExit(f"business: --route {text!r}: expected x,y:x,y[:x,y...] (metres)")
    lst = GTraceList(map=map_name.encode())
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        seg = lst.lists.add(finished=0.0)
        seg.first.x, seg.first.y, seg.first.angle = x0, y0, 0.0
        seg.second.x, seg.second.y, seg.second.angle = x1, y1, 0.0
        if speed > 0:
            seg.first.speed = speed  # mm/s
    lst.lists[0].first.starter = 1
    return lst


class Business:
    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.done = threading.Event()
        self.ok = False
        self.cancelled_at: float | None = None
        self.running_since: float | None = None
        self.pubs = {t: rospy.Publisher(t, Protobuf, queue_size=10) for t in (ROUTE, AVOID_ROUTE)}
        self.subs = [rospy.Subscriber(t, Protobuf, self.on_status, callback_args=t, queue_size=20)
                     for t in (STATUS, AVOID_STATUS)]

    def send(self, topic: str, msg: GTraceList) -> None:
        msg.ClearField("status")  # a request may omit it (the seed)
        self.pubs[topic].publish(Protobuf(type="GTraceList", data=msg.SerializeToString()))
        print(f"business: sent {len(msg.lists)} segment(s) on {topic}", flush=True)

    def on_status(self, env: Protobuf, topic: str) -> None:
        if env.type != "GTraceList":
            print(f"business: ignored a {env.type!r} on {topic}", flush=True)
            return
        msg = GTraceList.FromString(bytes(env.data))
        status = NAMES.get(msg.status, str(msg.status))
        done = ",".join(f"{s.finished:.3f}" for s in msg.lists)
        print(f"business: {topic} {status} finished={done}", flush=True)
        if self.cancelled_at is not None:
            if topic == STATUS and status == "IDLE":
                self.finish(True)
        elif topic == STATUS and status == "RUNNING" and self.running_since is None:
            self.running_since = rospy.get_time()
        elif topic == STATUS and status == "BLOCKED":
            self.send(AVOID_ROUTE, msg)  # 5. go around it
        elif topic == AVOID_STATUS and status == "FINISHED":
            self.send(ROUTE, msg)  # 8. resume where ObstacleNavigate says
        elif topic == AVOID_STATUS and status == "BLOCKED":
            self.finish(False)  # the detour failed
        elif topic == STATUS and status == "FINISHED":
            self.finish(True)  # 10.

    def finish(self, ok: bool) -> None:
        self.ok = ok
        self.done.set()

    def wait_for_subscribers(self, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end and not rospy.is_shutdown():
            ends = [*self.pubs.values(), *self.subs]
            if all(e.get_num_connections() > 0 for e in ends):
                return True
            time.sleep(0.05)
        return False

    def run(self) -> int:
        a = self.args
        if not self.wait_for_subscribers(a.connect_timeout):
            print("business: no TraceNavigate/ObstacleNavigate on the topics: start lowerbase "
                  "trace", file=sys.stderr)
            return 1
        route = route_list(a.route, a.map, a.speed)
        self.send(ROUTE, route)  # 1.
        end = time.monotonic() + a.timeout
        while not self.done.wait(0.05) and time.monotonic() < end and not rospy.is_shutdown():
            since = self.running_since
            if (a.cancel_after is not None and self.cancelled_at is None and since is not None
                    and rospy.get_time() >= since + a.cancel_after):
                self.cancelled_at = rospy.get_time()
                self.send(ROUTE, GTraceList(map=a.map.encode()))  # the empty list: cancel
        if not self.done.is_set():
            print(f"business: no end within {a.timeout} s", file=sys.stderr)
        print(f"business: {'done' if self.ok else 'failed'}", flush=True)
        return 0 if self.ok else 1


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--route", default="6,1.2:11,1.2:16,1.2:21,1.2", metavar="X,Y:X,Y...",
                   help="the route's points [m, map frame] (default: the warehouse's bottom "
                   "corridor)")
    p.add_argument("--map", default="warehouse", help="the map's name (GTraceList.map)")
    p.add_argument("--speed", type=int, default=500, help="[mm/s] of every segment")
    p.add_argument("--cancel-after", type=float, metavar="S",
                   help="send the empty list S s after the first RUNNING, wait for IDLE")
    p.add_argument("--timeout", type=float, default=300.0, metavar="S",
                   help="give up after S wall seconds (default 300)")
    p.add_argument("--connect-timeout", type=float, default=30.0, metavar="S")
    args = p.parse_args(rospy.myargv()[1:])
    rospy.init_node("business_node", anonymous=True)
    return Business(args).run()


if __name__ == "__main__":
    sys.exit(main())
