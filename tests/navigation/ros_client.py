"""A ROS client in a process of its own for the navigation node's black-box tests.

It runs actionlib's SimpleActionClient and rospy's ServiceProxy (the libraries a user of the
vendor's chassis calls) against the node, and answers one JSON request line with one JSON reply
line, as tests.driver.test_node_ros's probe does; a process of its own because rospy can
initialise one node per process and each test module has its own master.
"""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

SCRIPT = r'''
import json, math, sys, threading, time
import actionlib, genpy, rospy
from roslib.message import get_message_class, get_service_class

def plain(v):
    if hasattr(v, "__slots__"):
        if hasattr(v, "secs") and hasattr(v, "nsecs"):
            return v.secs + 1e-9 * v.nsecs
        return {k: plain(getattr(v, k)) for k in v.__slots__}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, bytes):
        return list(v)
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return v

def fill(msg, args):
    genpy.message.fill_message_args(msg, [args])
    return msg

rospy.init_node("nav_client", disable_signals=True)
lock = threading.Lock()
latest, counts, subs, pubs, clients, feedback = {}, {}, {}, {}, {}, {}

def subscribe(topic, type_name):
    if topic in subs:
        return
    def cb(msg, topic=topic):
        with lock:
            latest[topic] = msg
            counts[topic] = counts.get(topic, 0) + 1
    subs[topic] = rospy.Subscriber(topic, get_message_class(type_name), cb, queue_size=5)

def client(name, type_name):
    if name not in clients:
        c = actionlib.SimpleActionClient(name, get_message_class(type_name))
        if not c.wait_for_server(rospy.Duration(30.0)):
            raise RuntimeError(f"no action server {name}")
        clients[name] = c
    return clients[name]

def handle(req):
    op = req["op"]
    if op == "sub":
        subscribe(req["topic"], req["type"])
        return {}
    if op == "last":
        with lock:
            msg, n = latest.get(req["topic"]), counts.get(req["topic"], 0)
        return {"count": n, "msg": plain(msg) if msg is not None else None}
    if op == "pub":
        if req["topic"] not in pubs:
            pubs[req["topic"]] = rospy.Publisher(req["topic"], get_message_class(req["type"]),
                                                 queue_size=1, latch=True)
        pub = pubs[req["topic"]]
        deadline = time.monotonic() + 10.0
        while pub.get_num_connections() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        pub.publish(fill(get_message_class(req["type"])(), req["msg"]))
        return {"connections": pub.get_num_connections()}
    if op == "call":
        rospy.wait_for_service(req["name"], 30.0)
        cls = get_service_class(req["type"])
        proxy = rospy.ServiceProxy(req["name"], cls)
        return plain(proxy(fill(cls._request_class(), req.get("args", {}))))
    if op == "send":
        c = client(req["name"], req["type"])
        goal = fill(get_message_class(req["type"][:-6] + "Goal")(), req["goal"])
        feedback[req["name"]] = []
        def fb(msg, name=req["name"]):
            with lock:
                feedback[name].append(plain(msg))
        c.send_goal(goal, feedback_cb=fb)
        return {}
    if op == "feedback":
        with lock:
            got = list(feedback.get(req["name"], []))
        return {"count": len(got), "last": got[-1] if got else None}
    if op == "cancel":
        clients[req["name"]].cancel_goal()
        return {}
    if op == "state":
        c = clients[req["name"]]
        return {"state": c.get_state(), "text": c.get_goal_status_text()}
    if op == "result":
        c = clients[req["name"]]
        done = c.wait_for_result(rospy.Duration(req.get("timeout", 60.0)))
        result = c.get_result()
        with lock:
            n = len(feedback.get(req["name"], []))
        return {"done": done, "state": c.get_state(), "text": c.get_goal_status_text(),
                "result": plain(result) if result is not None else None, "feedbacks": n}
    raise ValueError(f"unknown op {op}")

print(json.dumps({"ready": True}), flush=True)
for line in sys.stdin:
    try:
        reply = handle(json.loads(line))
    except Exception as exc:
        reply = {"error": f"{type(exc).__name__}: {exc}"}
    print(json.dumps(reply), flush=True)
'''


class NavClient:
    """Talks to the client subprocess (see the module docstring)."""

    def __init__(self, tmp: Path, env: dict[str, str]) -> None:
        script = tmp / "nav_client.py"
        script.write_text(SCRIPT)
        self.popen = subprocess.Popen(
            [sys.executable, str(script)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True, env={**os.environ, **env})
        assert self._read(30.0) == {"ready": True}

    def _read(self, timeout: float) -> Any:
        assert self.popen.stdout is not None
        ready, _, _ = select.select([self.popen.stdout], [], [], timeout)
        line = self.popen.stdout.readline() if ready else ""
        if not line:
            self.popen.kill()
            _, err = self.popen.communicate()
            raise AssertionError(f"the ROS client gave no answer; stderr={err[-2000:]!r}")
        return json.loads(line)

    def ask(self, timeout: float = 90.0, **request: Any) -> Any:
        assert self.popen.stdin is not None
        self.popen.stdin.write(json.dumps(request) + "\n")
        self.popen.stdin.flush()
        reply = self._read(timeout)
        assert "error" not in reply, reply["error"]
        return reply

    def wait_last(self, topic: str, condition: Any, timeout: float, what: str) -> Any:
        """The latest message on ``topic`` once ``condition(msg)`` holds."""
        deadline = time.monotonic() + timeout
        last = None
        while time.monotonic() < deadline:
            last = self.ask(op="last", topic=topic)
            if last["msg"] is not None and condition(last["msg"]):
                return last["msg"]
            time.sleep(0.1)
        raise AssertionError(f"{what}: not seen within {timeout} s (last: {str(last)[:300]})")

    def close(self) -> None:
        if self.popen.stdin is not None:
            self.popen.stdin.close()
        try:
            self.popen.wait(10)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait()
