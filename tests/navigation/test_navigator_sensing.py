"""Never drive blind (issue 22 item 11): when the newest scan or localization is older than
``sensing_timeout`` the Navigator stops and waits (Status.WAITING, the goal stays ACTIVE), goes
on when sensing comes back, and gives up after ``sensing_patience``. The robot is integrated
from the commands (a unicycle at 20 Hz): the check is on the Navigator's own answers."""

from __future__ import annotations

import math

import pytest

from lowerbase.navigation.controller import Status
from lowerbase.navigation.navigator import GoalState, Navigator, NavigatorConfig
from lowerbase.world.maps import load_map

DT = 0.05


def _drive(nav: Navigator, pose: list[float], t0: float, seconds: float,
           sensed: float | None) -> list[tuple[float, float, float, Status, GoalState, str]]:
    """Ticks for ``seconds`` from ``t0``; ``sensed`` None: sensing fresh at every tick."""
    out = []
    for k in range(round(seconds / DT)):
        now = t0 + k * DT
        cmd = nav.tick(now, tuple(pose), now if sensed is None else sensed)
        out.append((now, cmd.linear, cmd.angular, cmd.status, cmd.state, cmd.reason))
        pose[0] += cmd.linear * math.cos(pose[2]) * DT
        pose[1] += cmd.linear * math.sin(pose[2]) * DT
        pose[2] += cmd.angular * DT
    return out


def test_stops_while_sensing_is_out_of_date_and_goes_on_when_it_returns() -> None:
    nav = Navigator(load_map("empty_room"))
    pose = [2.0, 3.0, 0.0]
    nav.send_goal((7.0, 3.0, 0.0))
    moving = _drive(nav, pose, 0.0, 2.0, None)
    assert max(v for _, v, *_ in moving) > 0.2
    frozen_at = 2.0 - DT  # the last fresh scan
    frozen = _drive(nav, pose, 2.0, 3.0, frozen_at)
    late = [r for r in frozen if r[0] - frozen_at > nav.config.sensing_timeout + 1e-9]
    assert late and all(r[1] == 0.0 and r[2] == 0.0 for r in late)  # not a metre blind
    assert all(r[3] is Status.WAITING and r[4] is GoalState.ACTIVE for r in late)
    assert "waiting for sensing" in late[-1][5]
    x_stopped = pose[0]
    _drive(nav, pose, 5.0, 30.0, None)
    assert nav.state is GoalState.SUCCEEDED, nav.reason
    assert pose[0] > x_stopped + 1.0


def test_gives_up_after_sensing_patience() -> None:
    nav = Navigator(load_map("empty_room"), NavigatorConfig(sensing_patience=4.0))
    pose = [2.0, 3.0, 0.0]
    nav.send_goal((7.0, 3.0, 0.0))
    _drive(nav, pose, 0.0, 1.0, None)
    rows = _drive(nav, pose, 1.0, 6.0, 0.95)
    aborted = [r for r in rows if r[4] is GoalState.ABORTED]
    assert aborted and nav.state is GoalState.ABORTED
    assert "sensing stopped" in nav.reason
    # stopped waiting from 0.5 s after the last scan, aborted 4 s later (not "stuck")
    assert aborted[0][0] - 0.95 == pytest.approx(0.5 + 4.0, abs=2 * DT)


def test_without_a_sensing_time_nothing_is_checked() -> None:
    nav = Navigator(load_map("empty_room"))
    nav.send_goal((7.0, 3.0, 0.0))
    pose = [2.0, 3.0, 0.0]
    for k in range(40):
        cmd = nav.tick(k * DT, tuple(pose))
        pose[0] += cmd.linear * DT
    assert cmd.status is not Status.WAITING and pose[0] > 2.2
