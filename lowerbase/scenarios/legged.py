"""Scenarios of the legged robot: ``[scenario] robot = "legged"`` (docs/legged.md).

The file has the wheeled scenario's four parts and its validation (:class:`~lowerbase.scenarios.
table.Table`: one line naming the file, the item and the problem), with the legged
robot's actions and expectations:

* actions: ``walk`` / ``stand`` / ``sit`` (the node's ``~walk`` ... goals), ``request``
  (one LocomotionRequest, ``state``), ``velocity`` (cmd_vel ``vx``, ``vy``, ``yaw_rate`` every
  50 ms for ``duration``), ``set_waypoints`` (``waypoints`` = [[x, y], [x, y, z], or tables
  {frame, x, y, z, use_z}], ``repetition``, ``current_index``), ``append_waypoint``
  (``waypoint``), ``get_waypoints``, ``set_listen`` (``data``), ``joy`` (``topic``, ``axes``,
  ``duration``: a sensor_msgs/Joy every 50 ms), and the fault injection ``heat`` (``joint``
  such as ``"FL_calf"``, ``temperature`` [degC]: the winding is that hot now);
* expectations: ``state``, ``fault``, ``position``, ``moving``, ``stopped``, ``laps``,
  ``actuator``, ``joy_listen_type``, ``answer`` (a service call's success and message).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from lowerbase.errors import ConfigError
from lowerbase.legged_driver.joystick import JoyListenType
from lowerbase.legged_driver.waypoints import ODOM, Waypoint
from lowerbase.protocol.legged import JOINT_NAMES, Fault, LocomotionState
from lowerbase.scenarios.expect import Outcome
from lowerbase.scenarios.table import Table as _Table

ROBOT = "legged"
GOAL_ACTIONS = {"walk": LocomotionState.IN_CONTROL, "stand": LocomotionState.STANDING_MODE,
                "sit": LocomotionState.SITDOWN_MODE}
SERVICES = ("set_waypoints", "append_waypoint", "get_waypoints", "set_listen")
PUBLISH_PERIOD = 0.05  #: [s] cmd_vel and Joy, as a teleop node sends them
STATES = {s.name: int(s) for s in LocomotionState}
FAULTS = {f.name: int(f) for f in Fault if f.name}
LISTEN = {t.name: int(t) for t in JoyListenType}


@dataclass(frozen=True)
class LeggedAction:
    at: float
    kind: str
    args: Mapping[str, Any] = field(default_factory=dict)
    duration: float = 0.0

    def label(self) -> str:
        shown = ", ".join(f"{k} {v}" for k, v in self.args.items() if k != "waypoints")
        return f"{self.kind}{' ' + shown if shown else ''}"

    @property
    def end(self) -> float:
        return self.at + self.duration


class LeggedTrace:
    """Samples by column name (NaN where a sample lacks the column)."""

    def __init__(self) -> None:
        self.rows: list[dict[str, float]] = []
        self._cache: dict[str, np.ndarray] = {}

    def append(self, sample: Mapping[str, float]) -> None:
        self.rows.append(dict(sample))
        self._cache.clear()

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._cache:
            self._cache[name] = np.array([r.get(name, math.nan) for r in self.rows])
        return self._cache[name]

    @property
    def columns(self) -> list[str]:
        return list(self.rows[0]) if self.rows else []

    @property
    def end(self) -> float:
        return float(self.rows[-1]["t"]) if self.rows else 0.0

    def select(self, at: float | None, during: tuple[float, float] | None) -> np.ndarray:
        """Indices of the samples at ``at`` (the last one at or before it; default the end)
        or within ``during``."""
        t = self["t"]
        if during is not None:
            return np.nonzero((t >= during[0] - 1e-9) & (t <= during[1] + 1e-9))[0]
        when = self.end if at is None else at
        i = int(np.searchsorted(t, when + 1e-9)) - 1
        return np.array([max(i, 0)]) if len(t) else np.zeros(0, dtype=int)


# -- expectations ------------------------------------------------------------------------------


@dataclass(frozen=True)
class LeggedExpectation:
    kind: str
    name: str
    at: float | None = None
    during: tuple[float, float] | None = None
    sometime: bool = False  #: during: at least one sample (else every sample)
    args: Mapping[str, Any] = field(default_factory=dict)

    LABELS: ClassVar[dict[str, str]] = {}

    def when(self) -> str:
        if self.during is not None:
            word = "sometime in" if self.sometime else "during"
            return f"{word} {self.during[0]:g}..{self.during[1]:g} s"
        return "at the end" if self.at is None else f"at {self.at:g} s"

    def describe(self) -> str:
        a = dict(self.args)
        if "column" in a:
            names = LISTEN if a.pop("column") == "joy_listen_type" else STATES
            value = a.pop("value")
            a["equals"] = next(k for k, v in names.items() if v == value)
        if self.kind == "fault":
            bit = a.pop("bit")
            a["bit"] = next((k for k, v in FAULTS.items() if v == bit), "none")
        shown = ", ".join(f"{k} {v}" for k, v in a.items())
        return f"{self.kind} {shown} {self.when()}"

    def title(self) -> str:
        return self.name or self.describe()

    def evaluate(self, trace: LeggedTrace, answers: Sequence[Answer] = ()) -> Outcome:
        if self.kind == "answer":
            return _answer(self, answers)
        rows = trace.select(self.at, self.during)
        if not len(rows):
            return Outcome("failed", "no sample in the window")
        ok, seen = _CHECKS[self.kind](self, trace, rows)
        passed = bool(ok.any()) if self.sometime else bool(ok.all())
        return Outcome("passed" if passed else "failed", seen)


@dataclass(frozen=True)
class Answer:
    t: float
    service: str
    success: bool
    message: str


def _answer(e: LeggedExpectation, answers: Sequence[Answer]) -> Outcome:
    a = e.args
    calls = [x for x in answers if x.service == a["service"] and abs(x.t - (e.at or 0)) < 1e-6]
    if not calls:
        return Outcome("failed", f"no {a['service']} call at {e.at:g} s")
    got = calls[0]
    ok = got.success == a["success"] and a.get("message", got.message) == got.message and \
        a.get("contains", "") in got.message
    return Outcome("passed" if ok else "failed", f"success {got.success}, {got.message!r}")


def _values(trace: LeggedTrace, rows: np.ndarray, column: str) -> np.ndarray:
    return trace[column][rows]


def _fmt(v: np.ndarray) -> str:
    u = np.unique(v[np.isfinite(v)])
    return ", ".join(f"{x:g}" for x in u[:6]) + (" ..." if len(u) > 6 else "")


def _check_state(e: LeggedExpectation, tr: LeggedTrace, rows: np.ndarray) -> tuple[Any, str]:
    v = _values(tr, rows, e.args["column"])
    names = {v: k for k, v in (LISTEN if e.args["column"] == "joy_listen_type"
                                else STATES).items()}
    seen = ", ".join(names.get(int(x), str(x)) for x in np.unique(v[np.isfinite(v)]))
    return v == e.args["value"], f"seen {seen or 'nothing'}"


def _check_fault(e: LeggedExpectation, tr: LeggedTrace, rows: np.ndarray) -> tuple[Any, str]:
    v = np.nan_to_num(_values(tr, rows, "fault")).astype(np.int64)
    bit = e.args["bit"]
    ok = (v & bit) != 0 if e.args["set"] else (v & bit) == 0 if bit else v == 0
    return ok, f"fault 0x{int(v[-1]):x} at the last sample"


def _check_position(e: LeggedExpectation, tr: LeggedTrace, rows: np.ndarray) -> tuple[Any, str]:
    err = np.zeros(len(rows))
    for axis in ("x", "y", "z"):
        if axis in e.args:
            err = err + (_values(tr, rows, axis) - e.args[axis]) ** 2
    err = np.sqrt(err)
    ok = err <= e.args["within"]
    if "truth_within" in e.args:  # robot_state's base_pos against the model's own pose
        truth = np.hypot(_values(tr, rows, "x") - _values(tr, rows, "truth_x"),
                         _values(tr, rows, "y") - _values(tr, rows, "truth_y"))
        ok = ok & (truth <= e.args["truth_within"])
        return ok, f"{err[-1]:.3f} m off, {truth[-1]:.4f} m from the truth"
    return ok, f"{err[-1]:.3f} m off"


def _speed(tr: LeggedTrace, rows: np.ndarray) -> np.ndarray:
    return np.hypot(_values(tr, rows, "vx"), _values(tr, rows, "vy"))


def _check_moving(e: LeggedExpectation, tr: LeggedTrace, rows: np.ndarray) -> tuple[Any, str]:
    s = _speed(tr, rows)
    return s >= e.args["speed"], f"max speed {np.nanmax(s):.3f} m/s"


def _check_stopped(e: LeggedExpectation, tr: LeggedTrace, rows: np.ndarray) -> tuple[Any, str]:
    s = _speed(tr, rows)
    return s < e.args["speed"], f"max speed {np.nanmax(s):.3f} m/s"


def _check_laps(e: LeggedExpectation, tr: LeggedTrace, rows: np.ndarray) -> tuple[Any, str]:
    laps, left = _values(tr, rows, "laps_done"), _values(tr, rows, "laps_left")
    ok = laps == e.args["equals"]
    if "left" in e.args:
        ok = ok & (left == e.args["left"])
    return ok, f"{laps[-1]:g} lap(s) walked, {left[-1]:g} left"


def _check_actuator(e: LeggedExpectation, tr: LeggedTrace, rows: np.ndarray) -> tuple[Any, str]:
    j = e.args["joint"]
    status, temp = _values(tr, rows, f"status_{j}"), _values(tr, rows, f"temp_{j}")
    ok = np.ones(len(rows), dtype=bool)
    if "status" in e.args:
        ok &= status == e.args["status"]
    ok &= (temp >= e.args.get("min_temperature", -math.inf)) & \
        (temp <= e.args.get("max_temperature", math.inf))
    return ok, f"{j}: status {_fmt(status)}, {np.nanmax(temp):.1f} degC max"


_CHECKS = {"state": _check_state, "joy_listen_type": _check_state, "fault": _check_fault,
           "position": _check_position, "moving": _check_moving, "stopped": _check_stopped,
           "laps": _check_laps, "actuator": _check_actuator}


# -- the scenario ------------------------------------------------------------------------------


@dataclass(frozen=True)
class LeggedScenario:
    name: str
    duration: float
    description: str = ""
    profile: Path | None = None
    soc: float = 80.0
    timeline: tuple[LeggedAction, ...] = ()
    expectations: tuple[LeggedExpectation, ...] = ()
    sample_period: float = 0.05
    source: str = "<dict>"
    robot: ClassVar[str] = ROBOT


_ACTION_KEYS: dict[str, set[str]] = {
    "walk": set(), "stand": set(), "sit": set(), "request": {"state"},
    "velocity": {"vx", "vy", "yaw_rate", "duration"},
    "set_waypoints": {"waypoints", "repetition", "current_index"},
    "append_waypoint": {"waypoint"}, "get_waypoints": set(), "set_listen": {"data"},
    "joy": {"topic", "axes", "duration"}, "heat": {"joint", "temperature"},
}


def _name(t: _Table, key: str, names: Mapping[str, int], default: str | None = None) -> int:
    value = t.text(key, default, choices=list(names))
    return names[value]


def waypoint_from(value: Any, where: str) -> Waypoint:
    """[x, y] / [x, y, z] in odom, or a table {frame, x, y, z, use_z}."""
    if isinstance(value, list):
        if not 2 <= len(value) <= 3 or any(isinstance(v, bool) or not isinstance(
                v, int | float) or not math.isfinite(v) for v in value):
            raise ConfigError(f"{where}: a waypoint is [x, y] or [x, y, z], not {value!r}")
        xyz = [float(v) for v in value] + [0.0]
        return Waypoint(ODOM, xyz[0], xyz[1], xyz[2])
    t = _Table(value, where)
    wp = Waypoint(t.text("frame", ODOM), t.number("x", required=True),
                  t.number("y", required=True), t.number("z", 0.0), t.flag("use_z", False))
    t.done()
    return wp


def _action(item: Any, index: int, duration: float) -> LeggedAction:
    t = _Table(item, f"timeline[{index}]")
    at = t.number("at", lo=0.0, hi=duration, required=True)
    t.where = f"timeline[{index}] (at {at:g} s)"
    kind = t.text("action", choices=list(_ACTION_KEYS))
    args: dict[str, Any] = {}
    length = 0.0
    if kind == "request":
        args["state"] = _name(t, "state", STATES)
    elif kind == "velocity":
        args.update(vx=t.number("vx", 0.0, lo=-3, hi=3), vy=t.number("vy", 0.0, lo=-3, hi=3),
                    yaw_rate=t.number("yaw_rate", 0.0, lo=-6, hi=6))
        length = t.number("duration", lo=0.0, hi=duration, required=True)
    elif kind == "set_waypoints":
        raw = t._get("waypoints")
        if not isinstance(raw, list):
            raise ConfigError(f"{t.where}: waypoints must be an array ([] for none)")
        args["waypoints"] = [waypoint_from(w, f"{t.where}: waypoints[{i}]")
                             for i, w in enumerate(raw)]
        args["repetition"] = int(t.number("repetition", 1, lo=0, hi=255))
        args["current_index"] = int(t.number("current_index", 0, lo=0, hi=255))
    elif kind == "append_waypoint":
        args["waypoint"] = waypoint_from(t._get("waypoint"), f"{t.where}: waypoint")
    elif kind == "set_listen":
        args["data"] = t.text("data")
    elif kind == "joy":
        args["topic"] = t.text("topic")
        axes = t._get("axes")
        if not isinstance(axes, list) or not all(
                isinstance(a, int | float) and not isinstance(a, bool) and -1 <= a <= 1
                for a in axes):
            raise ConfigError(f"{t.where}: axes must be an array of numbers in -1..1")
        args["axes"] = [float(a) for a in axes]
        length = t.number("duration", lo=0.0, hi=duration, required=True)
    elif kind == "heat":
        args["joint"] = t.text("joint", choices=JOINT_NAMES)
        args["temperature"] = t.number("temperature", lo=-40.0, hi=200.0, required=True)
    t.done({"at", "action", *_ACTION_KEYS[kind]})
    return LeggedAction(at, kind, args, length)


_EXPECT_KEYS: dict[str, set[str]] = {
    "state": {"equals"}, "joy_listen_type": {"equals"}, "fault": {"bit", "set"},
    "position": {"x", "y", "z", "within", "truth_within"}, "moving": {"speed"},
    "stopped": {"speed"}, "laps": {"equals", "left"},
    "actuator": {"joint", "status", "min_temperature", "max_temperature"},
    "answer": {"service", "success", "message", "contains"},
}


def _expectation(item: Any, index: int, duration: float) -> LeggedExpectation:
    t = _Table(item, f"expect[{index}]")
    kind = t.text("kind", choices=list(_EXPECT_KEYS))
    t.where = f"expect[{index}] ({kind})"
    name = t.text("name", "")
    at = t.opt_number("at", lo=0.0, hi=duration)
    during, sometime = t.interval("during"), False
    if t.has("sometime"):
        during, sometime = t.interval("sometime"), True
    if during is not None and at is not None:
        raise ConfigError(f"{t.where}: give at or during/sometime, not both")
    a: dict[str, Any] = {}
    if kind in ("state", "joy_listen_type"):
        a["column"] = kind
        a["value"] = _name(t, "equals", STATES if kind == "state" else LISTEN)
    elif kind == "fault":
        a["bit"] = _name(t, "bit", {"none": 0, **FAULTS})
        a["set"] = t.flag("set", a["bit"] != 0)
    elif kind == "position":
        for axis in ("x", "y", "z"):
            if t.has(axis):
                a[axis] = t.number(axis)
        if not a:
            raise ConfigError(f"{t.where}: give at least one of x, y, z")
        a["within"] = t.number("within", 0.1, lo=0.0)
        if t.has("truth_within"):
            a["truth_within"] = t.number("truth_within", lo=0.0)
    elif kind in ("moving", "stopped"):
        a["speed"] = t.number("speed", 0.05 if kind == "moving" else 0.02, lo=0.0)
        if kind == "moving":
            sometime = True
    elif kind == "laps":
        a["equals"] = int(t.number("equals", lo=0, hi=1e6, required=True))
        if t.has("left"):
            a["left"] = int(t.number("left", lo=0, hi=255))
    elif kind == "actuator":
        a["joint"] = t.text("joint", choices=JOINT_NAMES)
        for key in ("status", "min_temperature", "max_temperature"):
            if t.has(key):
                a[key] = t.number(key)
    elif kind == "answer":
        a["service"] = t.text("service", choices=SERVICES)
        a["success"] = t.flag("success", True)
        for key in ("message", "contains"):
            if t.has(key):
                a[key] = t.text(key)
        if at is None:
            raise ConfigError(f"{t.where}: at = the time of the call is required")
    if kind in ("moving", "stopped") and during is None and at is None:
        raise ConfigError(f"{t.where}: give during or sometime = [t1, t2]")
    t.done({"kind", "name", "at", "during", "sometime", *_EXPECT_KEYS[kind]})
    return LeggedExpectation(kind, name, at, during, sometime, a)


def legged_scenario_from_dict(data: Mapping[str, Any], source: str = "<dict>",
                              base: Path | None = None) -> LeggedScenario:
    """Build a legged scenario from parsed TOML; errors start with ``source``."""
    try:
        return _build(data, source, base)
    except ConfigError as e:
        raise ConfigError(f"{source}: {e}") from None


def _build(data: Mapping[str, Any], source: str, base: Path | None) -> LeggedScenario:
    _Table(data, "the file").done({"scenario", "initial", "timeline", "expect"})
    head = _Table(data.get("scenario", {}), "[scenario]")
    head.text("robot", choices=[ROBOT])
    duration = head.number("duration", lo=0.1, hi=3600.0, required=True)
    name = head.text("name", Path(source).stem)
    description = head.text("description", "")
    sample_period = head.number("sample_period", 0.05, lo=0.005, hi=1.0)
    profile_text = head.text("profile", "default")
    head.done()
    profile = None
    if profile_text != "default":
        profile = Path(profile_text)
        if not profile.is_absolute() and base is not None:
            profile = base / profile
        if not profile.is_file():
            raise ConfigError(f"[scenario]: profile {str(profile)!r} not found (a legged "
                              "profile TOML relative to the scenario file, or \"default\")")
    init = _Table(data.get("initial", {}), "[initial]")
    soc = init.number("soc", 80.0, lo=0.0, hi=100.0)
    init.done()
    items, checks = data.get("timeline", []), data.get("expect", [])
    if not isinstance(items, list) or not isinstance(checks, list):
        raise ConfigError("timeline and expect must be arrays of tables ([[timeline]], "
                          "[[expect]])")
    timeline = sorted((_action(x, i, duration) for i, x in enumerate(items)),
                      key=lambda a: a.at)
    expectations = tuple(_expectation(x, i, duration) for i, x in enumerate(checks))
    return LeggedScenario(name, duration, description, profile, soc, tuple(timeline),
                          expectations, sample_period, source)
