"""lowerbase.ros1.wire without ROS: a lockstep publisher is wanted while a face in the process
subscribes, a connection exists or the topic is latched; rospy's publish is skipped only
where it would do nothing (no connection, not latched)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from lowerbase.ros1.wire import Switchboard, _TeePublisher, connected, wanted


class FakeImpl:
    def __init__(self) -> None:
        self.connections: list[str] = []

    def has_connections(self) -> bool:
        return bool(self.connections)


class FakePublisher:
    def __init__(self) -> None:
        self.impl = FakeImpl()
        self.sent: list[Any] = []

    def publish(self, msg: Any) -> None:
        self.sent.append(msg)


def board() -> Switchboard:
    board = Switchboard.__new__(Switchboard)  # no tf2 buffer needed here
    board.local, board.latched, board._delivering = {}, {}, []
    board.stats = {"local": 0, "external": 0, "own_dropped": 0}
    return board


def test_unwanted_until_a_face_or_a_connection_takes_it() -> None:
    b, real = board(), FakePublisher()
    pub = _TeePublisher(real, b, "/odom_raw", latch=False)
    assert not wanted(pub)
    got: list[Any] = []
    b.add_local("/odom_raw", got.append)
    assert wanted(pub)
    b.remove_local("/odom_raw", got.append)
    real.impl.connections.append("client")
    assert wanted(pub)


def test_a_latched_topic_is_always_wanted_and_always_handed_to_rospy() -> None:
    real = FakePublisher()
    pub = _TeePublisher(real, board(), "/map", latch=True)
    assert wanted(pub)
    pub.publish("m")
    assert real.sent == ["m"]


def test_rospy_gets_a_message_only_with_a_connection() -> None:
    b, real = board(), FakePublisher()
    pub = _TeePublisher(real, b, "/scan", latch=False)
    got: list[Any] = []
    b.add_local("/scan", got.append)
    pub.publish("a")
    real.impl.connections.append("client")
    pub.publish("b")
    assert got == ["a", "b"] and real.sent == ["b"]


def test_a_publisher_that_cannot_be_asked_is_wanted_and_connected() -> None:
    plain = SimpleNamespace(publish=lambda msg: None)
    assert wanted(plain) and connected(plain) and connected(None)


def lazy_wire(b: Switchboard) -> Any:
    from lowerbase.ros1.wire import LocalWire

    wire = LocalWire.__new__(LocalWire)  # publish_lazy needs no rospy
    wire.board = b
    return wire


def test_a_lazy_message_is_built_only_when_read_or_sent_out() -> None:
    b, real = board(), FakePublisher()
    pub = _TeePublisher(real, b, "/scan", latch=False)
    wire = lazy_wire(b)
    built: list[int] = []

    def build() -> Any:
        built.append(1)
        return SimpleNamespace(header="h", ranges=[1.0, 2.0])

    got: list[Any] = []
    b.add_local("/scan", lambda m: got.append((m.header, b.convert(m, "scan", lambda _: "x"))))
    wire.publish_lazy(pub, "h", build, {"scan": lambda: "native"})
    assert got == [("h", "native")] and built == [] and real.sent == []
    # a face that reads the body gets the built message's, built once
    b.add_local("/scan", lambda m: got.append(m.ranges))
    wire.publish_lazy(pub, "h", build, {"scan": lambda: "native"})
    assert got[-1] == [1.0, 2.0] and built == [1] and real.sent == []
    real.impl.connections.append("outside")  # someone on ROS takes it: built, sent as is
    wire.publish_lazy(pub, "h", build, {"scan": lambda: "native"})
    assert built == [1, 1] and len(real.sent) == 1
    assert isinstance(real.sent[0], SimpleNamespace) and real.sent[0].ranges == [1.0, 2.0]


def test_a_connection_made_meanwhile_gets_the_built_message() -> None:
    from lowerbase.ros1.wire import LazyMessage

    b, real = board(), FakePublisher()
    pub = _TeePublisher(real, b, "/scan", latch=False)
    real.impl.connections.append("outside")
    pub.publish(LazyMessage("h", lambda: SimpleNamespace(header="h", ranges=[3.0])))
    assert real.sent[0].ranges == [3.0] and not isinstance(real.sent[0], LazyMessage)
