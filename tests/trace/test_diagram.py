"""The seed's sequence diagram, every numbered step, on the warehouse with a crate dropped on the
route, on the simulated clock (emulator + driver_base + world with amcl, as on a robot: the
crate is not on the map, so this also holds localization to the detour). A business node (a
listener on the status topics) answers as the seed says: BLOCKED -> the list to
ObstacleNavigate; its FINISHED -> the list back to TraceNavigate. blocked_timeout is 10 s
here (the 60 s default: test_trace_navigate.py)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import pytest

from lowerbase.trace import messages as m
from lowerbase.trace.sim import AVOID_ROUTE, AVOID_STATUS, ROUTE, SPEED, STATUS, TraceSim
from tests.trace.routes import CRATE, Y, route, trace_sim

XS = [6.0, 11.0, 16.0, 21.0]


@dataclass
class Run:
    sim: TraceSim
    contacts: int = 0
    cross: list[tuple[float, float]] = field(default_factory=list)  #: (x, |y - Y|) truth


@pytest.fixture(scope="module")
def run() -> Run:
    sim = trace_sim(crate=True, localization="filter", blocked_timeout=10.0)
    r = Run(sim)

    def business(topic: str, msg: m.GTraceList) -> None:
        if topic == STATUS and msg.status == m.BLOCKED:
            sim.publish(AVOID_ROUTE, msg)  # 5.
        elif topic == AVOID_STATUS and msg.status == m.FINISHED:
            sim.publish(ROUTE, msg)  # 8.

    sim.listeners.append(business)
    sim.publish(ROUTE, route(XS, starters=[0]))  # 1.

    def done() -> bool:
        x, y, _ = sim.world.true_pose()
        r.contacts += sim.world.contact is not None
        r.cross.append((x, abs(y - Y)))
        return any(msg.status == m.FINISHED for _, msg in sim.published[STATUS])

    assert sim.run_until(done, 150.0)
    sim.run(1.0)
    return r


def _reports(sim: TraceSim, topic: str) -> list[tuple[float, m.GTraceList]]:
    return sim.published[topic]  # type: ignore[return-value]


def test_1_2_trace_loop_reports_running_every_5s_with_finished(run: Run) -> None:
    reps = _reports(run.sim, STATUS)
    t0 = reps[0][0]
    running = [(t, r) for t, r in reps if r.status == m.RUNNING]
    first_block = next(t for t, r in reps if r.status == m.BLOCKED)
    before = [t for t, _ in running if t < first_block]
    assert before == pytest.approx([t0 + 5.0 * k for k in range(len(before))], abs=1e-6)
    assert len(before) >= 4
    fins = [[s.finished for s in r.lists] for t, r in running if t < first_block]
    for a, b in itertools.pairwise(fins):
        assert all(0.0 <= y <= 1.0 and y >= x for x, y in zip(a, b, strict=True))
    assert fins[2][0] > 0.9 or fins[3][0] == 1.0  # segment 0 (5 m at 0.5 m/s) done by ~10 s
    assert all(r.HasField("status") and r.map == b"warehouse" for _, r in reps)


def test_3_4_stops_before_the_crate_and_reports_blocked_after_the_wait(run: Run) -> None:
    reps = _reports(run.sim, STATUS)
    t_block, blocked = next((t, r) for t, r in reps if r.status == m.BLOCKED)
    crate_face = CRATE["center"][0] - 0.2  # type: ignore[index]
    # where it stood: the fraction of segment 1 (11 -> 16) it reached, in front of the crate
    x_stop = 11.0 + 5.0 * blocked.lists[1].finished
    assert blocked.lists[0].finished == 1.0 and blocked.lists[2].finished == 0.0
    assert crate_face - 1.2 < x_stop + 0.5 < crate_face  # the front stops short of it
    # it stood still for the whole 10 s before BLOCKED (speed commands ~0 meanwhile)
    speeds = [(t, s.linear) for t, s in run.sim.published[SPEED] if t_block - 9.0 <= t < t_block]
    assert speeds and max(abs(v) for _, v in speeds) < 1e-3
    assert run.contacts == 0


def test_5_6_7_obstacle_navigate_goes_around_and_says_where_to_continue(run: Run) -> None:
    reps = _reports(run.sim, AVOID_STATUS)
    t_block = next(t for t, r in _reports(run.sim, STATUS) if r.status == m.BLOCKED)
    assert reps[0][0] == pytest.approx(t_block) and reps[0][1].status == m.RUNNING
    _t_done, done = next((t, r) for t, r in reps if r.status == m.FINISHED)
    assert [r.status for _, r in reps].count(m.FINISHED) == 1
    fin = [s.finished for s in done.lists]
    rejoin_x = 11.0 + 5.0 * fin[1]
    assert fin[0] == 1.0 and fin[2] == 0.0
    assert rejoin_x > CRATE["center"][0] + 0.2 + 0.5  # type: ignore[index]
    # it really left the line to pass the crate, and touched nothing
    off = [d for x, d in run.cross if 12.7 < x < 13.3]
    assert off and min(off) > 0.55
    assert run.contacts == 0
    assert run.sim.obstacle.status == m.IDLE


def test_8_9_10_trace_resumes_and_finishes_at_the_end(run: Run) -> None:
    reps = _reports(run.sim, STATUS)
    t_avoided = next(t for t, r in _reports(run.sim, AVOID_STATUS) if r.status == m.FINISHED)
    after = [(t, r) for t, r in reps if t >= t_avoided]
    assert after[0][1].status == m.RUNNING and after[0][0] == pytest.approx(t_avoided)
    assert after[-1][1].status == m.FINISHED
    assert [s.finished for s in after[-1][1].lists] == [1.0, 1.0, 1.0]
    assert [r.status for _, r in reps].count(m.FINISHED) == 1  # momentary: once, then IDLE
    assert run.sim.trace.status == m.IDLE
    x, y, yaw = run.sim.world.true_pose()
    assert math.hypot(x - XS[-1], y - Y) < 0.06 and abs(yaw) < math.radians(3)
    # silent on speed after FINISHED: the last command is the zero at the end
    t_end = after[-1][0]
    last = [(t, s) for t, s in run.sim.published[SPEED] if t >= t_end]
    assert last and all(t == t_end and s.linear == s.angular == 0.0 for t, s in last)


def test_cross_track_along_the_straight_segments(run: Run) -> None:
    # the truth's distance to the line: the controller's error (<= 3 cm, benchmarks/bench_trace
    # on ground truth) plus amcl's sideways error in the corridor (3-4 cm p95, docs/world.md)
    on_line = sorted(d for x, d in run.cross if 7.0 < x < 11.5 or 16.0 < x < 20.5)
    p95 = on_line[int(0.95 * (len(on_line) - 1))]
    assert p95 <= 0.05
