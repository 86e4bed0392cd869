"""lowerbase.ros1.wire without ROS: an external input's rospy subscription never connects to this
process' own publisher of the topic, and still connects to everyone else's."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from lowerbase.ros1.wire import _skip_own_publisher

OWN = "http://localhost:40001/"
OTHER = "http://otherhost:40002/"


class FakeImpl:
    """rospy's _SubscriberImpl as far as its connecting is concerned."""

    def __init__(self) -> None:
        self.connected: set[str] = set()

    def has_connection(self, endpoint_id: str) -> bool:
        return endpoint_id in self.connected


def fake_rospy() -> Any:
    return SimpleNamespace(core=SimpleNamespace(get_node_uri=lambda: OWN))


def test_the_own_publisher_counts_as_connected_and_others_do_not() -> None:
    impl = FakeImpl()
    _skip_own_publisher(fake_rospy(), SimpleNamespace(impl=impl))
    assert impl.has_connection(OWN)
    assert not impl.has_connection(OTHER)
    impl.connected.add(OTHER)
    assert impl.has_connection(OTHER)


def test_two_subscribers_of_one_topic_wrap_it_once() -> None:
    impl = FakeImpl()
    for _ in range(2):
        _skip_own_publisher(fake_rospy(), SimpleNamespace(impl=impl))
    wrapped = impl.has_connection
    _skip_own_publisher(fake_rospy(), SimpleNamespace(impl=impl))
    assert impl.has_connection is wrapped
    assert impl.has_connection(OWN) and not impl.has_connection(OTHER)
