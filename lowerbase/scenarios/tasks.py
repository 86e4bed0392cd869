"""Task scenarios: exec_task requests and move_base goals on the whole robot, simulated clock.

A task scenario is a scenario file with a ``[tasks]`` table (it needs a ``[world]``, read by
:func:`lowerbase.scenarios.world.parse_world`); it runs on a
:class:`~lowerbase.tasks.sim.TaskSim` (emulator, driver core, world, localization, navigator,
task machine) in one process (:mod:`lowerbase.scenarios.tasks_run`; its report:
:mod:`lowerbase.reports.tasks`; `lowerbase scenario run` loads it for files with
``[tasks]``)::

    [scenario]
    name = "transport"; duration = 120.0      # [s] simulated (up to 8 h)
    [initial]
    soc = 80.0
    [world]
    map = "empty_room"
    [tasks]                                   # TaskConfig: load_time, unload_time, full_soc,
    unload_time = 5.0                         # dock_timeout, auto_charge, blocked_delay
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
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError, LowerbaseError
from lowerbase.files import read_toml
from lowerbase.tasks.model import (
    ActionState,
    ActionType,
    RobotState,
    TaskRequest,
    TaskState,
)

TASK_KEYS = {"load_time", "unload_time", "full_soc", "dock_timeout", "auto_charge",
             "blocked_delay"}
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

    def title(self) -> str:
        return self.describe()

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
    source: str = ""

    @property
    def expectations(self) -> list[Expect]:
        return self.expects


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
        from lowerbase.scenarios.timeline import CONTROL_ACTIONS

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
    path = Path(path)
    return tasks_scenario_from_dict(read_toml(path, "scenario"), path, path.parent)


def tasks_scenario_from_dict(data: Mapping[str, Any], path: str | Path,
                             base: Path) -> TasksScenario:
    """A task scenario from parsed TOML (``path``: its name in messages and its default name;
    ``base``: where relative map paths start)."""
    from lowerbase.scenarios.world import parse_world
    from lowerbase.tasks.plan import TaskConfig

    path = Path(path)
    unknown = sorted(set(data) - {"scenario", "initial", "world", "tasks", "timeline", "expect"})
    if unknown:
        raise ConfigError(f"{path}: unknown table {unknown[0]!r}")
    head = data.get("scenario", {})
    duration = _num(head, "duration", "[scenario]", None, 0.1, MAX_DURATION)
    if "world" not in data or "tasks" not in data:
        raise ConfigError(f"{path}: a task scenario needs [world] and [tasks] tables")
    world = parse_world(data["world"], base)
    tasks = data["tasks"]
    bad = sorted(set(tasks) - TASK_KEYS)
    if bad:
        raise ConfigError(f"[tasks]: unknown key {bad[0]!r}; known: {', '.join(sorted(TASK_KEYS))}")
    for key, value in tasks.items():
        if key == "auto_charge" and not isinstance(value, bool):
            raise ConfigError(f"[tasks]: auto_charge must be true or false, not {value!r}")
        if key != "auto_charge" and (isinstance(value, bool)
                                     or not isinstance(value, int | float)):
            raise ConfigError(f"[tasks]: {key} must be a number, not {value!r}")
    try:
        config = TaskConfig(**tasks)
    except LowerbaseError as e:
        raise ConfigError(f"[tasks]: {e}") from None
    timeline = [_step(t, f"timeline[{i}]", duration)
                for i, t in enumerate(data.get("timeline", []))]
    expects = [_expect(t, f"expect[{i}]") for i, t in enumerate(data.get("expect", []))]
    return TasksScenario(str(head.get("name", path.stem)), duration,
                         _num(data.get("initial", {}), "soc", "[initial]", 80.0, 0.0, 100.0),
                         world, config, sorted(timeline, key=lambda s: s.at), expects,
                         str(head.get("description", "")), str(path))


def library_tasks() -> dict[str, Path]:
    """The library's task scenarios (scenarios/tasks/*.toml) by name."""
    here = Path(__file__).resolve()
    for d in (here.parents[2] / "scenarios" / "tasks", here.parent / "library" / "tasks"):
        if d.is_dir():
            return {p.stem: p for p in sorted(d.glob("*.toml"))}
    return {}
