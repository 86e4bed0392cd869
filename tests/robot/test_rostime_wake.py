"""lowerbase.robot.lockstep.RosTime: ROS time is set at every step, rospy's sleepers are woken
once per wake period of simulated time (and at the first setting): by default actionlib's
status period, found as actionlib finds it."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

rostime = pytest.importorskip("rospy.rostime")

from lowerbase.robot.lockstep import RosTime, status_period  # noqa: E402


def test_time_set_every_step_and_sleepers_woken_once_a_period(
        monkeypatch: pytest.MonkeyPatch) -> None:
    woken: list[float] = []

    def wake(t: Any) -> None:
        woken.append(t)
        rostime._rostime_current = t

    monkeypatch.setattr(rostime, "_set_rostime", wake)
    monkeypatch.setattr(rostime, "_rostime_current", None)
    fake = SimpleNamespace(Time=SimpleNamespace(from_sec=float))
    clock = RosTime(fake, wake_period=0.05)
    for k in range(25):  # 0 .. 0.12 s in 5 ms steps
        clock.set(k * 0.005)
        assert rostime._rostime_current == k * 0.005
    assert woken == pytest.approx([0.0, 0.05, 0.1])


@pytest.mark.parametrize(("params", "period"), [({}, 0.2),
                                                ({"/actionlib_status_frequency": 10.0}, 0.1),
                                                ({"/actionlib_status_frequency": 0.0}, 1.0)])
def test_the_wake_period_is_actionlibs_status_period(params: dict[str, float],
                                                       period: float) -> None:
    fake = SimpleNamespace(
        search_param=lambda name: f"/{name}" if f"/{name}" in params else None,
        get_param=lambda name, default=None: params.get(name, default),
        Time=SimpleNamespace(from_sec=float))
    assert status_period(fake) == pytest.approx(period)
    assert RosTime(fake).wake_period == pytest.approx(period)
