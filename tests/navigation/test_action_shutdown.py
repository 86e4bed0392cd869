"""At rospy's shutdown the navigation node's action servers stop their timed status (actionlib's
own timer callback, no master): a tick between rospy's on_shutdown hooks and its shutdown flag
published to a closed topic and left a traceback in navigation.log (seen once in CI)."""

from __future__ import annotations

import threading
from typing import Any

from tests.driver.conftest import require_ros


class Inner:
    """actionlib.ActionServer's state that its status timer reads."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.started = True
        self.published = 0

    def publish_status(self) -> None:
        self.published += 1


class Server:
    def __init__(self) -> None:
        self.action_server = Inner()


class FakeRospy:
    def __init__(self) -> None:
        self.hooks: list[Any] = []

    def on_shutdown(self, hook: Any) -> None:
        self.hooks.append(hook)


def test_the_status_timer_is_quiet_once_rospy_begins_to_shut_down() -> None:
    require_ros(("rospy", "actionlib"))
    from actionlib.action_server import ActionServer  # type: ignore[import-untyped]

    from lowerbase.navigation.actions import ActionServers

    servers = ActionServers.__new__(ActionServers)
    servers.move_base, servers.steps, servers.mode = Server(), Server(), Server()
    for s in (servers.move_base, servers.steps, servers.mode):
        s.start = lambda: None  # type: ignore[attr-defined]
    rospy = FakeRospy()
    servers.node = type("Node", (), {"rospy": rospy})()
    servers.start()
    inners = [s.action_server for s in (servers.move_base, servers.steps, servers.mode)]
    for inner in inners:  # running: actionlib's timer callback publishes
        ActionServer.publish_status_async(inner, None)
    assert [i.published for i in inners] == [1, 1, 1]
    assert rospy.hooks == [servers.quiet]
    rospy.hooks[0]()  # rospy.signal_shutdown runs the on_shutdown hooks first
    for inner in inners:
        ActionServer.publish_status_async(inner, None)
    assert [i.published for i in inners] == [1, 1, 1]
