"""lowerbase.robot.lockstep.RosTime: ROS time is set at every step, rospy's sleepers are woken
once per WAKE_PERIOD of simulated time (and at the first setting)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

rostime = pytest.importorskip("rospy.rostime")

from lowerbase.robot.lockstep import RosTime  # noqa: E402


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
