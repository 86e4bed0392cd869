"""Running a task scenario (scenario_tasks.py) on a TaskSim on the simulated clock: the
timeline, the expectations, and what the report draws (samples of the truth, the
localization estimate, the battery and robot_status; the navigator's plans).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from lowerbase.recording.world import attach_world, world_topics
from lowerbase.scenarios.tasks import FIELDS, Expect, Step, TasksScenario
from lowerbase.tasks.model import FINAL_STATES, Status, TaskState

SAMPLE_PERIOD = 0.25  #: [s] simulated, between two rows of TasksResult.samples
#: TasksResult.samples columns: truth and localization estimate (map frame; NaN: none yet),
#: the BMS's SOC and current as the driver reads them, the pack model's exact SOC and current,
#: the charger contact (1 closed), and the machine's current robot_status fields
SAMPLE_COLUMNS = ("t", "truth_x", "truth_y", "truth_yaw", "est_x", "est_y", "est_yaw", "soc",
                  "current", "pack_soc", "pack_current", "charger", "task_id", "task_state",
                  "action_type", "action_state", "robot_state")



@dataclass
class TasksResult:
    scenario: TasksScenario
    history: list[tuple[float, Status]] = field(default_factory=list)
    outcomes: list[tuple[Expect, bool, str]] = field(default_factory=list)
    responses: list[tuple[float, int, bool, str]] = field(default_factory=list)
    sim: Any = None  #: the TaskSim it ran on (its world's truth, the BMS)
    samples: list[tuple[float, ...]] = field(default_factory=list)  #: SAMPLE_COLUMNS rows
    plans: list[tuple[float, list[tuple[float, float, float]]]] = field(default_factory=list)
    interrupted: bool = False  #: Ctrl-C ended the run early
    wall_time: float = 0.0

    @property
    def passed(self) -> bool:
        return all(ok for _, ok, _ in self.outcomes)



def build(sc: TasksScenario, on_status: Callable[[Status], None] | None = None,
          tap: Any = None) -> Any:
    """The TaskSim a scenario runs on (``tap(t, direction, frame_id, data)``: every frame)."""
    from lowerbase.navigation.sim import NavSim
    from lowerbase.simloop.loop import SimLoop
    from lowerbase.tasks.sim import TaskSim
    from lowerbase.world.sim import WorldSim

    world = WorldSim(sc.world.config(), loop=SimLoop(soc=sc.soc, tap=tap))
    return TaskSim(NavSim(world), config=sc.config, on_status=on_status)


def _apply(ts: Any, step: Step, result: TasksResult) -> None:
    if step.kind == "exec_task":
        assert step.request is not None
        res = ts.request(step.request)
        result.responses.append((ts.now, step.request.task_id, res.success, res.message))
    elif step.kind == "move_base":
        target = step.target
        if isinstance(target, str):
            target = ts.places.named()[target]
        ts.navsim.navigator.send_goal(target, (), 0, ts.now)
    elif step.kind == "fault":
        from lowerbase.firmware_model.faults import Fault, parse_fault

        f = parse_fault(step.fault)
        if step.duration is not None:
            f = Fault(f.kind, f.arg, 0.0, step.duration)
        ts.world.loop.mcu.inject(f)
    elif step.kind == "control":
        ts.world.loop.driver.control(step.fault)
    else:
        ts.world.loop.mcu.clear_fault()


def run_tasks_scenario(sc: TasksScenario,
                       progress: Callable[[float, Any], None] | None = None,
                       publisher: Any = None) -> TasksResult:
    """Run ``sc`` on the simulated clock and evaluate its expectations. Every SAMPLE_PERIOD
    a row of ``samples`` is taken and ``progress(t, sim)`` called; each new plan of the
    navigator goes to ``plans``. Ctrl-C ends the run early (``interrupted``; ``sim`` is None
    when it came before the robot was built).

    ``publisher``: a ``lowerbase.recording.publisher.RunPublisher`` (an MCAP file, the live
    view) that gets the run as it goes: every frame, the driver's topics and the truth, the
    world's, each plan and each robot_status; the caller closes it. It does not change the
    run (tested)."""
    result = TasksResult(sc)
    holder: list[Any] = []

    def on_status(s: Status) -> None:
        t = holder[0].now if holder else 0.0
        result.history.append((t, s))
        if publisher is not None:
            publisher.robot_status(t, s)

    wall0 = time.monotonic()
    pending = list(sc.timeline)
    next_sample, path = 0.0, None
    try:
        ts = build(sc, on_status, publisher)
        holder.append(ts)
        result.sim = ts
        if publisher is not None:
            _attach(publisher, ts)
        while ts.now < sc.duration - 1e-9:
            while pending and pending[0].at <= ts.now + 1e-9 and (
                    not pending[0].idle or not ts.machine.active):
                _apply(ts, pending.pop(0), result)
            if ts.now + 1e-9 >= next_sample:
                next_sample += SAMPLE_PERIOD
                result.samples.append(sample(ts))
                if progress is not None:
                    progress(ts.now, ts)
            ts.tick()
            if ts.navsim.navigator.path is not path:
                path = ts.navsim.navigator.path
                if path:
                    poses = [(float(p[0]), float(p[1]), float(p[2])) for p in path]
                    result.plans.append((ts.now, poses))
                    if publisher is not None:
                        world_topics(publisher).plan(ts.now, poses)
        result.samples.append(sample(ts))
    except KeyboardInterrupt:
        result.interrupted = True
        if result.sim is not None:  # the report's last row: where the robot stopped
            result.samples.append(sample(result.sim))
    result.wall_time = time.monotonic() - wall0
    result.outcomes = [(e, *evaluate(e, result.history)) for e in sc.expects]
    return result


def _attach(publisher: Any, ts: Any) -> None:
    """The driver's topics with the truth next to /odom, and the world's topics."""
    loop = ts.world.loop
    tr = loop.mcu.truth
    publisher.attach(loop.driver, loop.clock.now, lambda: (tr.x, tr.y, tr.yaw, tr.v, tr.w))
    attach_world(publisher, ts.world)


def sample(ts: Any) -> tuple[float, ...]:
    """A row of SAMPLE_COLUMNS now."""
    w, nan = ts.world, math.nan
    est = w.amcl_pose() or (nan, nan, nan)
    snap = w.loop.driver.bms.snapshot()
    pack = getattr(getattr(w.loop.mcu.bms, "device", None), "pack", None)
    st = ts.machine.tracker.current
    fields = (st.task_id, st.task_state, st.action_type, st.action_state, st.robot_state) \
        if st is not None else (nan,) * 5
    return (ts.now, *w.true_pose(), *est,
            float(snap.soc) if snap is not None else nan,
            float(snap.current) if snap is not None else nan,
            float(pack.soc) if pack is not None else nan,
            float(pack.current) if pack is not None else nan,
            float(ts.charger_closed), *(float(f) for f in fields))


def evaluate(e: Expect, history: list[tuple[float, Status]]) -> tuple[bool, str]:
    mine = [(t, s) for t, s in history if s.task_id == e.task_id and s.task_type]
    if e.kind == "tasks_completed":
        done, prev = 0, None
        for _, s in history:
            key = (s.task_id, s.task_state)
            if s.task_state == TaskState.COMPLETED and key != prev:
                done += 1
            prev = key
        return done >= e.at_least, f"{done} completed"
    if not mine:
        return False, f"task {e.task_id} never published"
    if e.kind == "robot_status":
        seen: list[int] = []
        for _, s in mine:
            v = int(getattr(s, e.field))
            if not seen or seen[-1] != v:
                seen.append(v)
        it = iter(seen)
        ok = all(any(v == want for v in it) for want in e.sequence)
        names = " -> ".join(FIELDS[e.field](v).name.lower() for v in seen)
        return ok, f"seen {names}"
    ends = [t for t, s in mine if s.task_state in FINAL_STATES]
    if not ends:
        return False, f"task {e.task_id} did not end"
    took = ends[0] - mine[0][0]
    return e.within[0] <= took <= e.within[1], f"took {took:.1f} s"


def report(result: TasksResult) -> str:
    lines = [f"{result.scenario.name}: {'PASSED' if result.passed else 'FAILED'}"]
    lines += [f"  {'ok ' if ok else 'BAD'} {e.describe()}: {why}" for e, ok, why in
              result.outcomes]
    return "\n".join(lines)
