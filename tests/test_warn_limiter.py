"""WarnLimiter: one warning per period, with the count and the worst value since the last."""

from __future__ import annotations

from lowerbase.clock import WarnLimiter


def test_the_first_event_is_said_then_one_per_period_with_what_came_between() -> None:
    w = WarnLimiter(10.0)
    assert w.take(100.0, 0.2) == (1, 0.2)
    assert w.take(101.0, 0.9) is None
    assert w.take(109.9, 0.3) is None
    assert w.take(110.0, 0.1) == (3, 0.9)  # 101, 109.9 and 110.0; the worst of them 0.9
    assert w.take(119.0) is None
    assert w.take(125.0, -1.0) == (2, 0.0)  # the default value counts too


def test_a_zero_period_says_every_event() -> None:
    w = WarnLimiter(0.0)
    assert [w.take(t) for t in (1.0, 1.0, 2.0)] == [(1, 0.0), (1, 0.0), (1, 0.0)]
