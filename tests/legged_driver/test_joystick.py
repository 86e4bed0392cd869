"""set_listen hand-over rules and the Joy -> body velocity mapping."""

from __future__ import annotations

import math

import pytest

from lowerbase.legged_driver.joystick import JoyHandover, JoyListenType, JoyMapping, parse


def test_parse_the_seeds_strings() -> None:
    assert parse("joy<&>my_app") == ("joy", "my_app")
    assert parse("/ns/joy<&><CLOSE>") == ("/ns/joy", "<CLOSE>")
    for bad in ("joy", "joy<&>", "<&>app", "joy<&>a<&>b", "jo y<&>app", "joy!<&>app"):
        with pytest.raises(ValueError):
            parse(bad)


@pytest.mark.parametrize("topic", ["/", "//joy", "joy/", "/ns//joy", "1joy", "/ns/2x", "~",
                                   "~/joy", "/_joy", "jo~y", "/ns/joy/"])
def test_set_listen_refuses_topics_that_are_not_ros_names(topic: str) -> None:
    """Issue 22 item 21: "/<&>x" was accepted, then rospy logged FATAL subscribing to it."""
    with pytest.raises(ValueError, match="is not a ROS topic name"):
        parse(f"{topic}<&>x")
    hand = JoyHandover()
    ok, msg = hand.request(f"{topic}<&>x")
    assert not ok and hand.holder is None and "\n" not in msg


def test_legal_topic_names_and_long_input_quoted_short() -> None:
    for topic in ("joy", "/joy", "~joy", "/ns/joy_1", "ns/Joy2", "a"):
        assert parse(f"{topic}<&>app") == (topic, "app")
    ok, msg = JoyHandover().request("/" * 100_000 + "<&>x")
    assert not ok and len(msg) < 250 and "(100000 chars)" in msg


def test_hand_over_and_take_back() -> None:
    h = JoyHandover()
    assert h.listen_type is JoyListenType.VEL_CMD and h.command(0.0) is None
    assert h.request("joy<&>my_app") == (True, "joystick control handed to 'my_app' on topic "
                                               "'joy'")
    assert h.listen_type is JoyListenType.JOY and h.holder is not None
    ok, msg = h.request("joy2<&>other")
    assert not ok and msg == ("joystick control is held by 'my_app' on 'joy'; it must release "
                              "it first ('joy<&><CLOSE>')")
    assert h.holder.client == "my_app"
    ok, msg = h.request("joy2<&><CLOSE>")
    assert not ok and "send 'joy<&><CLOSE>'" in msg and h.listen_type is JoyListenType.JOY
    assert h.request("joy<&><CLOSE>") == (True, "joystick control taken back from 'my_app'")
    assert h.listen_type is JoyListenType.VEL_CMD and h.command(0.0) is None
    ok, msg = h.request("joy<&><CLOSE>")
    assert not ok and "nothing to close" in msg
    assert h.request("joy2<&>other")[0]  # free again: another client may take it
    assert h.request("joy3<&>other")[0] and h.holder.topic == "joy3"  # holder moves topic
    assert not h.request("garbage")[0] and h.holder.topic == "joy3"
    assert JoyHandover(default_type=JoyListenType.NONE).listen_type is JoyListenType.NONE


def test_joy_drives_only_from_the_holders_topic_and_goes_stale() -> None:
    h = JoyHandover(JoyMapping(max_linear=0.8, max_lateral=0.4, max_angular=1.2),
                    joy_timeout=0.5)
    assert not h.on_joy("joy", [0.0, 1.0], 0.0) and h.rejected_joy == 1
    h.request("joy<&>app")
    assert not h.on_joy("other", [0.0, 1.0], 0.0) and h.rejected_joy == 2
    assert h.command(0.0) == (0.0, 0.0, 0.0)  # no Joy yet
    assert h.on_joy("joy", [-0.5, 1.0, 0.0, 0.25], 1.0)
    assert h.command(1.2) == pytest.approx((0.8, -0.2, 0.3))
    assert h.command(1.6) == (0.0, 0.0, 0.0)  # stale after 0.5 s
    h.on_joy("joy", [0.02, 2.0, 0.0, math.nan], 2.0)  # deadzone, clipped, NaN -> 0
    assert h.command(2.0) == pytest.approx((0.8, 0.0, 0.0))
    h.on_joy("joy", [], 3.0)  # a short axes array: missing axes are 0
    assert h.command(3.0) == (0.0, 0.0, 0.0)
