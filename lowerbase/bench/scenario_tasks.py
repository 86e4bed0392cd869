"""Task scenarios: exec_task requests and move_base goals on the whole robot, simulated clock.

A task scenario is a scenario file with a ``[tasks]`` table (it needs a ``[world]``, read by
:func:`lowerbase.bench.scenario_world.parse_world`); it runs on a
:class:`~lowerbase.tasks.sim.TaskSim` (emulator, driver core, world, localization, navigator,
task machine) in one process::

    [scenario]
    name = "transport"; duration = 120.0      # [s] simulated (up to 8 h)
    [initial]
    soc = 80.0
    [world]
    map = "empty_room"
    [tasks]                                   # TaskConfig: load_time, unload_time, full_soc,
    unload_time = 5.0                         # dock_timeout, auto_charge
    [[timeline]]
    at = 1.0                                  # [s]; with when = "idle": the first moment from
    when = "idle"                             # `at` on that no task runs (a queue of work)
    action = "exec_task"                      # task_exect (1), task_id, task_type, direction,
    task_id = 1; task_type = 4; mark_no = "R1"  # mark_no, poses = [[x, y, yaw], ...]
    [[timeline]]
    at = 5.0; action = "move_base"; mark = "R2"   # or target = [x, y, yaw]: the navigator
    [[timeline]]
    at = 8.0; fault = "estop"; duration = 3.0 # a lower-computer fault (firmware_model.faults)
    [[timeline]]
    at = 9.0; action = "clear_fault"          # the faults end
    [[timeline]]
    at = 9.5; action = "control"; command = "FaultClear"  # a ControlCommand by the driver
    [[expect]]
    kind = "robot_status"; task_id = 1        # the task's published values of `field`
    field = "task_state"                      # (names or codes; repeats collapsed) contain
    sequence = ["executing", "completed"]     # `sequence` in this order
    [[expect]]
    kind = "task_duration"; task_id = 1; within = [10.0, 60.0]  # first status to its end [s]
    [[expect]]
    kind = "tasks_completed"; at_least = 3    # tasks (own charging included) completed
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError
from lowerbase.files import read_toml
from lowerbase.tasks.model import (
    FINAL_STATES,
    ActionState,
    ActionType,
    RobotState,
    Status,
    TaskRequest,
    TaskState,
)

TASK_KEYS = {"load_time", "unload_time", "full_soc", "dock_timeout", "auto_charge"}
FIELDS: dict[str, type[IntEnum]] = {"task_state": TaskState, "action_type": ActionType,
                           "action_state": ActionState, "robot_state": RobotState}
MAX_DURATION = 8 * 3600.0


@dataclass(frozen=True)
class Step:
    """A timeline entry: ``kind`` exec_task / move_base / fault / clear_fault / control
    (``fault``: the fault spec, or the ControlCommand)."""

    at: float
    kind: str
    idle: bool = False
    request: TaskRequest | None = None
    target: tuple[float, float, float] | str | None = None
    fault: str = ""
    duration: float | None = None


@dataclass(frozen=True)
class Expect:
    kind: str
    task_id: int = 0
    field: str = "task_state"
    sequence: tuple[int, ...] = ()
    within: tuple[float, float] = (0.0, math.inf)
    at_least: int = 0

    def describe(self) -> str:
        if self.kind == "robot_status":
            names = [FIELDS[self.field](v).name.lower() for v in self.sequence]
            return f"task {self.task_id}: {self.field} goes {' -> '.join(names)}"
        if self.kind == "task_duration":
            return f"task {self.task_id} takes {self.within[0]:g} .. {self.within[1]:g} s"
        return f"at least {self.at_least} tasks completed"


@dataclass
class TasksScenario:
    name: str
    duration: float
    soc: float
    world: Any
    config: Any
    timeline: list[Step]
    expects: list[Expect]
    description: str = ""


@dataclass
class TasksResult:
    scenario: TasksScenario
    history: list[tuple[float, Status]] = field(default_factory=list)
    outcomes: list[tuple[Expect, bool, str]] = field(default_factory=list)
    responses: list[tuple[float, int, bool, str]] = field(default_factory=list)
    sim: Any = None  #: the TaskSim it ran on (its world's truth, the BMS)

    @property
    def passed(self) -> bool:
        return all(ok for _, ok, _ in self.outcomes)


def _num(t: Mapping[str, Any], key: str, where: str, default: float | None = None,
         lo: float = -math.inf, hi: float = math.inf) -> float:
    v = t.get(key, default)
    if v is None or isinstance(v, bool) or not isinstance(v, int | float) or \
            not (math.isfinite(v) and lo <= v <= hi):
        raise ConfigError(f"{where}: {key} must be a number in [{lo:g}, {hi:g}], not {v!r}")
    return float(v)


def _int(t: Mapping[str, Any], key: str, where: str, default: int = 0) -> int:
    v = t.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int):
        raise ConfigError(f"{where}: {key} must be an integer, not {v!r}")
    return v


def _pose(v: Any, where: str) -> tuple[float, float, float]:
    if not isinstance(v, list) or len(v) != 3 or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in v):
        raise ConfigError(f"{where}: a pose is [x, y, yaw] numbers, not {v!r}")
    return float(v[0]), float(v[1]), float(v[2])


def _step(t: Any, where: str, duration: float) -> Step:
    if not isinstance(t, Mapping):
        raise ConfigError(f"{where}: must be a table")
    at = _num(t, "at", where, None, 0.0, duration)
    idle = t.get("when", "at") == "idle"
    if t.get("when", "at") not in ("at", "idle"):
        raise ConfigError(f"{where}: when must be \"at\" or \"idle\", not {t.get('when')!r}")
    if "fault" in t:
        from lowerbase.firmware_model.faults import parse_fault

        parse_fault(str(t["fault"]))  # a bad spec: one ConfigError line now
        length = _num(t, "duration", where, None, 0.0, MAX_DURATION) if "duration" in t else None
        return Step(at, "fault", fault=str(t["fault"]), duration=length)
    kind = t.get("action")
    if kind == "clear_fault":
        return Step(at, kind)
    if kind == "control":
        from lowerbase.bench.scenario import CONTROL_ACTIONS

        command = t.get("command")
        if command not in CONTROL_ACTIONS.values():
            raise ConfigError(f"{where}: command must be one of "
                              f"{', '.join(CONTROL_ACTIONS.values())}, not {command!r}")
        return Step(at, kind, fault=str(command))
    if kind == "move_base":
        target: tuple[float, float, float] | str
        if "mark" in t:
            target = str(t["mark"])
        elif "target" in t:
            target = _pose(t["target"], where)
        else:
            raise ConfigError(f"{where}: move_base needs mark = NAME or target = [x, y, yaw]")
        return Step(at, kind, idle, target=target)
    if kind == "exec_task":
        poses = t.get("poses", [])
        if not isinstance(poses, list):
            raise ConfigError(f"{where}: poses must be an array of [x, y, yaw]")
        req = TaskRequest(_int(t, "task_exect", where, 1), _int(t, "task_id", where),
                          _int(t, "task_type", where), _int(t, "direction", where),
                          0, str(t.get("mark_no", "")),
                          tuple(_pose(p, where) for p in poses))
        return Step(at, kind, idle, request=req)
    raise ConfigError(f"{where}: action must be exec_task, move_base, control or clear_fault "
                      f"(or give fault = SPEC), not {kind!r}")


def _codes(field_name: str, values: Any, where: str) -> tuple[int, ...]:
    enum = FIELDS[field_name]
    if not isinstance(values, list) or not values:
        raise ConfigError(f"{where}: sequence must be a non-empty array")
    out = []
    for v in values:
        try:
            out.append(int(enum[str(v).upper()]) if isinstance(v, str) else int(enum(v)))
        except (KeyError, ValueError):
            names = ", ".join(m.name.lower() for m in enum)
            raise ConfigError(f"{where}: {v!r} is not a {field_name}; one of {names}") from None
    return tuple(out)


def _expect(t: Any, where: str) -> Expect:
    if not isinstance(t, Mapping):
        raise ConfigError(f"{where}: must be a table")
    kind = t.get("kind")
    if kind == "robot_status":
        name = str(t.get("field", "task_state"))
        if name not in FIELDS:
            raise ConfigError(f"{where}: field must be one of {', '.join(FIELDS)}")
        return Expect(kind, _int(t, "task_id", where), name,
                      _codes(name, t.get("sequence"), where))
    if kind == "task_duration":
        w = t.get("within")
        if not isinstance(w, list) or len(w) != 2:
            raise ConfigError(f"{where}: within = [min, max] seconds")
        return Expect(kind, _int(t, "task_id", where),
                      within=(_num({"v": w[0]}, "v", where), _num({"v": w[1]}, "v", where)))
    if kind == "tasks_completed":
        return Expect(kind, at_least=_int(t, "at_least", where, 1))
    raise ConfigError(f"{where}: kind must be robot_status, task_duration or tasks_completed, "
                      f"not {kind!r}")


def load_tasks_scenario(path: str | Path) -> TasksScenario:
    """A task scenario file; every mistake is one ConfigError line."""
    from lowerbase.bench.scenario_world import parse_world
    from lowerbase.tasks.plan import TaskConfig

    path = Path(path)
    data = read_toml(path, "scenario")
    unknown = sorted(set(data) - {"scenario", "initial", "world", "tasks", "timeline", "expect"})
    if unknown:
        raise ConfigError(f"{path}: unknown table {unknown[0]!r}")
    head = data.get("scenario", {})
    duration = _num(head, "duration", "[scenario]", None, 0.1, MAX_DURATION)
    if "world" not in data or "tasks" not in data:
        raise ConfigError(f"{path}: a task scenario needs [world] and [tasks] tables")
    world = parse_world(data["world"], path.parent)
    tasks = data["tasks"]
    bad = sorted(set(tasks) - TASK_KEYS)
    if bad:
        raise ConfigError(f"[tasks]: unknown key {bad[0]!r}; known: {', '.join(sorted(TASK_KEYS))}")
    config = TaskConfig(**tasks)
    timeline = [_step(t, f"timeline[{i}]", duration)
                for i, t in enumerate(data.get("timeline", []))]
    expects = [_expect(t, f"expect[{i}]") for i, t in enumerate(data.get("expect", []))]
    return TasksScenario(str(head.get("name", path.stem)), duration,
                         _num(data.get("initial", {}), "soc", "[initial]", 80.0, 0.0, 100.0),
                         world, config, sorted(timeline, key=lambda s: s.at), expects,
                         str(head.get("description", "")))


def library_tasks() -> dict[str, Path]:
    """The library's task scenarios (scenarios/tasks/*.toml) by name."""
    here = Path(__file__).resolve()
    for d in (here.parents[2] / "scenarios" / "tasks", here.parent / "scenarios" / "tasks"):
        if d.is_dir():
            return {p.stem: p for p in sorted(d.glob("*.toml"))}
    return {}


def build(sc: TasksScenario, on_status: Callable[[Status], None] | None = None) -> Any:
    """The TaskSim a scenario runs on."""
    from lowerbase.bench.simloop import SimLoop
    from lowerbase.navigation.sim import NavSim
    from lowerbase.tasks.sim import TaskSim
    from lowerbase.world.sim import WorldSim

    world = WorldSim(sc.world.config(), loop=SimLoop(soc=sc.soc))
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


def run_tasks_scenario(sc: TasksScenario) -> TasksResult:
    """Run ``sc`` on the simulated clock and evaluate its expectations."""
    result = TasksResult(sc)
    holder: list[Any] = []

    def on_status(s: Status) -> None:
        result.history.append((holder[0].now if holder else 0.0, s))

    ts = build(sc, on_status)
    holder.append(ts)
    result.sim = ts
    pending = list(sc.timeline)
    while ts.now < sc.duration - 1e-9:
        while pending and pending[0].at <= ts.now + 1e-9 and (
                not pending[0].idle or not ts.machine.active):
            _apply(ts, pending.pop(0), result)
        ts.tick()
    result.outcomes = [(e, *evaluate(e, result.history)) for e in sc.expects]
    return result


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
