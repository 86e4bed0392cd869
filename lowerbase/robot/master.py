"""The ROS master of ``lowerbase robot``: the one in ROS_MASTER_URI when it answers, else a
``rosmaster --core`` of our own on that URI's port, on loopback (ROS_IP=127.0.0.1), which ends
with the robot."""

from __future__ import annotations

import os
import shutil
import socket
import time
import urllib.parse
import xmlrpc.client
from typing import Any

from lowerbase.robot.supervisor import ChildSpec, RobotError

DEFAULT_MASTER_URI = "http://localhost:11311"
LOCAL_HOSTS = ("localhost", "127.0.0.1", "::1", "")


def master_uri(env: dict[str, str] | None = None) -> str:
    return (env if env is not None else dict(os.environ)).get("ROS_MASTER_URI") \
        or DEFAULT_MASTER_URI


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout: float) -> None:
        super().__init__()
        self._timeout = timeout

    def make_connection(self, host: Any) -> Any:
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn


def master_answers(uri: str, timeout: float = 1.0) -> bool:
    """True when a ROS master answers getPid at ``uri``."""
    try:
        proxy = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout))
        reply: Any = proxy.getPid("/lowerbase_robot")
        code = reply[0]
        return bool(code == 1)
    except (OSError, xmlrpc.client.Error, ValueError):
        return False


def is_local(uri: str) -> bool:
    host = urllib.parse.urlsplit(uri).hostname or ""
    return host in LOCAL_HOSTS or host.startswith("127.") or host == socket.gethostname()


def own_master(uri: str) -> ChildSpec:
    """The ``rosmaster --core`` to start for ``uri`` (a local one that does not answer)."""
    if not is_local(uri):
        raise RobotError(f"no ROS master answers at {uri}; start roscore there, or unset "
                         "ROS_MASTER_URI to let lowerbase robot start its own")
    if shutil.which("rosmaster") is None:
        raise RobotError("rosmaster is not on PATH; run scripts/install-ros.sh as root "
                         "(or `make env`)")
    port = urllib.parse.urlsplit(uri).port or 11311
    return ChildSpec("rosmaster", ["rosmaster", "--core", "-p", str(port)], ready_text=None,
                     env={"ROS_IP": "127.0.0.1"})


def wait_for_master(uri: str, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if master_answers(uri, 0.5):
            return
        time.sleep(0.1)
    raise RobotError(f"the ROS master at {uri} did not come up in {timeout:g} s; is the port "
                     "in use? set ROS_MASTER_URI=http://localhost:PORT with a free PORT")


def set_param(uri: str, name: str, value: Any) -> None:
    proxy = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(2.0))
    reply: Any = proxy.setParam("/lowerbase_robot", name, value)
    code, msg = reply[0], reply[1]
    if code != 1:
        raise RobotError(f"cannot set {name} on the ROS master at {uri}: {msg}")


def get_param(uri: str, name: str) -> Any:
    """The value of ``name`` on the master, or None when it is not set."""
    proxy = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(2.0))
    reply: Any = proxy.getParam("/lowerbase_robot", name)
    return reply[2] if reply[0] == 1 else None


def delete_param(uri: str, name: str) -> None:
    proxy = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(2.0))
    proxy.deleteParam("/lowerbase_robot", name)


#: the node names a lowerbase robot registers (lockstep: the first; process per part: the rest)
ROBOT_NODES = ("/lowerbase_robot", "/driver_base", "/world", "/move_base", "/tasks",
               "/legged_driver")


def running_robot(uri: str) -> str | None:
    """The name of a robot node that is registered on the master at ``uri`` and answers (a
    robot is running there: a second one would take its names, and ROS would shut the first
    one's nodes down), or None."""
    proxy = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(2.0))
    for name in ROBOT_NODES:
        try:
            reply: Any = proxy.lookupNode("/lowerbase_robot_check", name)
        except (OSError, xmlrpc.client.Error):
            return None
        if reply[0] != 1:
            continue
        try:
            node = xmlrpc.client.ServerProxy(reply[2], transport=_TimeoutTransport(1.0))
            answer: Any = node.getPid("/lowerbase_robot_check")
            if answer[0] == 1:
                return f"{name} (pid {answer[2]})"
        except (OSError, xmlrpc.client.Error, ValueError):
            continue  # registered by a process that is gone: not running
    return None
