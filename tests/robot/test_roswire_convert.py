"""lowerbase.ros1.wire's conversions in-process (needs rospy and tf2_ros, no master: the
switchboard's tf2 buffer is a stand-in): each delivered message is converted once for all its
local subscribers, or taken from its publisher."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from tests.driver.conftest import require_ros


@pytest.fixture()
def board(monkeypatch: pytest.MonkeyPatch) -> Any:
    require_ros(("rospy", "tf2_ros"))
    import rospy
    import tf2_ros

    from lowerbase.ros1.wire import Switchboard

    monkeypatch.setattr(tf2_ros, "Buffer", lambda **kwargs: None)  # a real one wants a master

    return Switchboard(rospy, external=frozenset())


def test_one_conversion_per_delivery_shared_by_the_subscribers(board: Any) -> None:
    calls: list[Any] = []
    got: list[Any] = []

    def conversion(msg: Any) -> Any:
        calls.append(msg)
        return ("pose", msg.n)

    for _ in range(3):
        board.add_local("/odom", lambda m: got.append(board.convert(m, "pose", conversion)))
    for n in range(2):
        board.deliver("/odom", SimpleNamespace(n=n), latch=False)
    assert got == [("pose", 0)] * 3 + [("pose", 1)] * 3
    assert len(calls) == 2
    outside = SimpleNamespace(n=7)  # not being delivered: converted every time
    assert board.convert(outside, "pose", conversion) == ("pose", 7)
    assert board.convert(outside, "pose", conversion) == ("pose", 7)
    assert len(calls) == 4


def test_the_publishers_value_is_taken_and_made_only_when_asked(board: Any) -> None:
    made: list[int] = []
    got: list[Any] = []

    def make() -> str:
        made.append(1)
        return "native"

    board.deliver("/scan", SimpleNamespace(), latch=False, converted={"scan": make})
    assert made == []  # nobody listens: nothing made
    board.add_local("/scan", lambda m: got.append(board.convert(m, "scan", lambda _: "back")))
    board.add_local("/scan", lambda m: got.append(board.convert(m, "other", lambda _: "conv")))
    board.deliver("/scan", SimpleNamespace(), latch=False, converted={"scan": make})
    assert got == ["native", "conv"] and made == [1]


def test_an_error_reaches_every_subscriber(board: Any) -> None:
    errors: list[str] = []

    def bad(msg: Any) -> Any:
        raise ValueError("not a pose")

    def subscriber(m: Any) -> None:
        try:
            board.convert(m, "pose", bad)
        except ValueError as exc:
            errors.append(str(exc))

    board.add_local("/odom", subscriber)
    board.add_local("/odom", subscriber)
    board.deliver("/odom", SimpleNamespace(), latch=False)
    assert errors == ["not a pose"] * 2
