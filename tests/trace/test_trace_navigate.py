"""TraceNavigate's defined answers on the simulated chassis: the empty-list cancel, bad input,
a list while one runs, the nearest starter, resuming from ``finished``, the 60 s default wait."""

from __future__ import annotations

import math

import pytest

from lowerbase.clock import SimClock
from lowerbase.trace import messages as m
from lowerbase.trace import modules
from lowerbase.trace.base import POSE_HISTORY
from lowerbase.trace.sim import ROUTE, SPEED, STATUS, TraceSim
from lowerbase.world.maps import load_map
from tests.trace.routes import Y, route, trace_sim


def _statuses(sim: TraceSim) -> list[int]:
    return [s for _, s in sim.statuses(STATUS)]


def test_empty_list_cancels_zero_speed_at_once_idle_once() -> None:
    sim = trace_sim()
    sim.publish(ROUTE, route([6.0, 11.0]))
    sim.run(3.0)
    assert sim.world.loop.mcu.truth.v > 0.3
    t = sim.now
    sim.publish(ROUTE, m.GTraceList(map=b"warehouse"))
    zero = [s for ts, s in sim.published[SPEED] if ts == t]
    assert zero and zero[-1].linear == zero[-1].angular == 0.0
    sim.run(2.0)
    assert abs(sim.world.loop.mcu.truth.v) < 1e-3
    assert _statuses(sim) == [m.RUNNING, m.IDLE]
    assert [ts for ts, _ in sim.published[SPEED] if ts > t] == []  # silent after


@pytest.mark.parametrize("edit, why", [
    (lambda r: setattr(r.lists[0].second, "x", r.lists[0].first.x), "length"),
    (lambda r: setattr(r.lists[0].first, "y", math.nan), "finite"),
    (lambda r: setattr(r.lists[0], "finished", 1.5), "0..1"),
    (lambda r: setattr(r, "map", b"corridor_loop"), "map"),
])
def test_bad_lists_are_refused_with_idle_and_nothing_moves(edit: object, why: str,
                                                           caplog: pytest.LogCaptureFixture
                                                           ) -> None:
    sim = trace_sim()
    lst = route([6.0, 11.0])
    edit(lst)  # type: ignore[operator]
    sim.publish(ROUTE, lst)
    sim.run(1.0)
    assert _statuses(sim) == [m.IDLE] and sim.trace.stats["refused"] == 1
    assert why in caplog.text
    assert abs(sim.world.true_pose()[0] - 6.0) < 1e-3 and not sim.published[SPEED]


def test_a_list_while_one_runs_is_refused_and_the_run_goes_on() -> None:
    sim = trace_sim()
    sim.publish(ROUTE, route([6.0, 9.0]))
    sim.run(2.0)
    sim.publish(ROUTE, route([6.0, 6.0 + 0.5], y=2.0))
    assert sim.trace.stats["refused"] == 1
    answer = sim.published[STATUS][-1][1]
    assert answer.status == m.RUNNING and answer.lists[0].second.x == 9.0  # type: ignore
    assert sim.run_until(lambda: sim.trace.status == m.IDLE, 30.0)
    assert _statuses(sim)[-1] == m.FINISHED
    assert abs(sim.world.true_pose()[0] - 9.0) < 0.05


def test_starts_at_the_nearest_starter_and_drives_the_rest() -> None:
    sim = trace_sim(start_x=11.2)
    sim.publish(ROUTE, route([6.0, 8.5, 11.0, 13.0], starters=[0, 2]))
    assert sim.run_until(lambda: sim.trace.status == m.IDLE, 30.0)
    final = sim.published[STATUS][-1][1]
    assert final.status == m.FINISHED  # type: ignore[attr-defined]
    assert [s.finished for s in final.lists] == [0.0, 0.0, 1.0]  # type: ignore[attr-defined]
    assert abs(sim.world.true_pose()[0] - 13.0) < 0.05


def test_resumes_from_finished_and_speed_is_mm_per_s() -> None:
    sim = trace_sim(start_x=8.5)
    sim.publish(ROUTE, route([6.0, 11.0, 14.0], finished=[0.5, 0.0], speed=300))
    sim.run(6.0)
    assert sim.world.loop.mcu.truth.v == pytest.approx(0.3, abs=0.02)
    assert sim.run_until(lambda: sim.trace.status == m.IDLE, 40.0)
    final = sim.published[STATUS][-1][1]
    assert [s.finished for s in final.lists] == [1.0, 1.0]  # type: ignore[attr-defined]


def test_default_wait_is_60s_on_the_sim_clock() -> None:
    sim = trace_sim(start_x=11.0, crate=True)
    assert sim.params.blocked_timeout == 60.0 and sim.params.status_period == 5.0
    sim.publish(ROUTE, route([11.0, 16.0]))
    assert sim.run_until(lambda: sim.trace.status == m.BLOCKED, 90.0)
    t_block = sim.published[STATUS][-1][0]
    moving = [t for t, s in sim.published[SPEED] if abs(s.linear) > 1e-3]
    assert t_block - moving[-1] == pytest.approx(60.0, abs=0.5)  # stopped, then 60 s
    assert sim.world.true_pose()[1] == pytest.approx(Y, abs=0.03)


def test_a_point_off_the_map_is_refused_by_both_modules() -> None:
    """A 10 m map (empty_room, 10 x 8.6 m) and a point at x = 50: refused with IDLE and the
    reason, as move_base refuses an off-map goal; no speed is sent."""
    lst = route([2.0, 50.0], y=2.0)
    lst.map = b""
    with pytest.raises(m.TraceError, match=r"segment 0 second point \(50.00, 2.00\) is off "
                       r"the map \(x 0.00..10.00 m, y 0.00..8.60 m\)"):
        m.check_route(lst, extent=(0.0, 0.0, 10.0, 8.6))
    lst.lists[0].second.x = 1e300
    with pytest.raises(m.TraceError, match=r"\(1e\+300, 2.00\) is off the map"):
        m.check_route(lst, extent=(0.0, 0.0, 10.0, 8.6))
    lst.lists[0].second.x = 50.0
    sent: list[tuple[str, object]] = []
    mods = modules.TraceModules(SimClock(), load_map("empty_room"),
                                lambda t, msg: sent.append((t, msg)))
    mods.deliver(modules.POSE, m.RobotPose2D(x=2.0, y=2.0, theta=0.0))
    for topic, status in ((modules.ROUTE, modules.STATUS),
                          (modules.AVOID_ROUTE, modules.AVOID_STATUS)):
        mods.deliver(topic, lst)
        assert [(t, msg.status) for t, msg in sent] == [(status, m.IDLE)]  # type: ignore
        sent.clear()
    for _ in range(10):
        mods.tick()
    assert sent == []
    assert mods.trace.stats["refused"] == mods.obstacle.stats["refused"] == 1


def test_a_robot_off_the_route_drives_to_its_start_first_and_reports_only_what_it_drove(
        ) -> None:
    """Issue 22 item 17: a route from x = 4 while the robot stands at x = 6 on its line. It
    used to cut in at 6 and report the first 40 % as driven; it drives back to 4, turns along
    the route and drives all of it; no report is ever ahead of the robot."""
    sim = trace_sim(start_x=6.0)
    sim.publish(ROUTE, route([4.0, 9.0]))
    seen: list[tuple[float, float]] = []  # (time, true x)

    def idle() -> bool:
        seen.append((sim.now, sim.world.true_pose()[0]))
        return sim.trace.status == m.IDLE

    assert sim.run_until(idle, 80.0)
    assert min(x for _, x in seen) < 4.1  # it went to the start
    assert abs(seen[-1][1] - 9.0) < 0.06
    reports = sim.published[STATUS]
    assert reports[-1][1].lists[0].finished == 1.0  # type: ignore[attr-defined]
    at_start = next(ts for ts, x in seen if x < 4.1)
    for t, msg in reports:
        done = msg.lists[0].finished  # type: ignore[attr-defined]
        if t < at_start:
            assert done == 0.0, (t, done)  # nothing driven on the way to the start
        else:
            x = [x for ts, x in seen if ts <= t + 1e-9][-1]
            assert 4.0 + 5.0 * done <= x + 0.1, (t, done, x)
    assert len(reports) >= 4  # on the 5 s grid while it drove back and along


def test_reports_stay_on_the_5s_grid_after_a_stall() -> None:
    """Issue 22 item 18: the 5 s reports drifted to 2.8-16 s under load. A tick 12 s late gives
    one report (not three in a burst) and the next ones stay on the acceptance time's grid."""
    from lowerbase.trace.trace_navigate import TraceNavigate

    clock = SimClock(100.0)
    nav = TraceNavigate(clock, lambda msg: None, lambda msg: None,
                        extent=load_map("warehouse").extent)
    nav.on_route(route([6.0, 11.0]))
    nav.pose = (6.0, Y, 0.0)
    times = []
    for t in (100.0, 105.0, 117.0, 117.05, 119.95, 120.0, 125.0):
        clock.sleep_until(t)
        before = len(nav.reports)
        nav.tick()
        times += [clock.now() - 100.0] * (len(nav.reports) - before)
    assert times == [5.0, 17.0, 20.0, 25.0]  # acceptance's report at 0 is on_route's


def _scan(stamp: float) -> m.GLaserScan:
    return m.GLaserScan(stamp=stamp, frame_id="base_link", angle_min=-0.5, angle_max=0.5,
                        angle_increment=0.5, time_increment=0.0, scan_time=0.1,
                        range_min=0.05, range_max=20.0, ranges=[2.0, 2.0, 2.0])


def test_a_late_scan_is_paired_with_the_pose_of_its_time() -> None:
    """Issue 22 item 18: on a busy host a scan arrives after the robot has turned on; it is
    marked from the pose of its stamp (tf's message filter), not the latest one (which smeared
    obstacles over the route, so ObstacleNavigate found no clear rejoin point). A scan newer
    than every pose waits for the next; one older than every pose kept is dropped, counted."""
    mods = modules.TraceModules(SimClock(), load_map("empty_room"), lambda t, msg: None)
    nav = mods.obstacle
    poses = [(1.0 + 0.05 * k, (2.0 + 0.01 * k, 2.0, 0.1 * k)) for k in range(6)]
    for stamp, (x, y, yaw) in poses:
        mods.deliver(modules.POSE, m.RobotPose2D(stamp=stamp, x=x, y=y, theta=yaw))
    mods.deliver(modules.LASER, _scan(1.1))  # arrives at 1.25: the robot turned 0.3 rad since
    assert nav._latest is not None and nav._latest[0] == poses[2][1]
    mods.deliver(modules.LASER, _scan(1.27))  # newer than every pose: waits
    assert nav._latest[0] == poses[2][1] and nav._latest[1].stamp == pytest.approx(1.1)
    mods.deliver(modules.POSE, m.RobotPose2D(stamp=1.3, x=2.2, y=2.0, theta=0.6))
    assert nav._latest[0] == (2.2, 2.0, 0.6) and nav._latest[1].stamp == pytest.approx(1.27)
    for k in range(POSE_HISTORY):
        mods.deliver(modules.POSE, m.RobotPose2D(stamp=2.0 + 0.05 * k, x=2.0, y=2.0))
    mods.deliver(modules.LASER, _scan(1.5))  # older than every pose kept
    assert nav.stats["scan_too_old"] == 1 and nav._latest[1].stamp == pytest.approx(1.27)
    # unstamped messages keep the old pairing: the latest pose
    mods.deliver(modules.LASER, _scan(0.0))
    assert nav._latest[1].stamp == 0.0 and nav._latest[0] == (2.0, 2.0, 0.0)


def test_every_pose_pairs_with_a_scan_when_poses_lag_by_more_than_a_scan_period() -> None:
    """CI under load: the localization's pose (map -> base_link at the last localized scan's
    time) lagged the newest scan by more than a scan period; with one waiting slot each new
    scan replaced the one the next pose would have taken, no scan was ever marked and the
    robot stood BLOCKED at the route's start. Scans at 25 Hz, poses at 20 Hz arriving 120 ms
    after their stamps: each pose takes the newest scan it reaches, older waiting ones are
    superseded."""
    mods = modules.TraceModules(SimClock(), load_map("empty_room"), lambda t, msg: None)
    nav = mods.obstacle
    taken: dict[float, float] = {}  # scan stamp -> stamp of the pose it was marked from
    scan_t = [1.0 + 0.04 * k for k in range(101)]
    pose_t = [0.9 + 0.05 * k for k in range(81)]
    arrivals = sorted([(t, 0, t) for t in scan_t] + [(t + 0.12, 1, t) for t in pose_t])
    for _, kind, t in arrivals:
        if kind == 0:
            mods.deliver(modules.LASER, _scan(t))
        else:
            mods.deliver(modules.POSE, m.RobotPose2D(stamp=t, x=2.0 + t, y=2.0))
        if nav._latest is not None:
            pose, scan = nav._latest
            taken.setdefault(scan.stamp, pose[0] - 2.0)
    assert len(taken) >= 75  # a scan for (nearly) every pose from the first scan's on
    for scan_stamp, pose_stamp in taken.items():  # the first pose at or after the scan
        assert scan_stamp - 1e-9 <= pose_stamp < scan_stamp + 0.05, (scan_stamp, pose_stamp)
    ignored = sum(t < pose_t[0] + 0.12 for t in scan_t)  # before any pose: not kept
    assert nav.stats["scan_superseded"] == \
        len(scan_t) - ignored - len(taken) - len(nav._waiting)
    assert nav.stats["scan_too_old"] == 0 and len(nav._waiting) <= 4
