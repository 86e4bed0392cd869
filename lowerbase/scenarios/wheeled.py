"""Scenarios: a run of the chassis described in a TOML file, and the checks made on it.

A scenario names a profile, the initial state (SOC, pose, charger), a timeline of actions (what
the upper computer or the world does: twist segments, LED commands, parameter writes, e-stop,
charger, lower-computer reboot, ...) and of faults (``lowerbase.firmware_model.faults`` specs),
and expectations ("stopped within 0.6 s of t = 5", "WATCHDOG_STOP set during [6, 8]", "/odom
within 0.05 m of the truth at the end", "SOC between 79 and 80"). docs/scenarios.md is the
reference of the file format; ``load_scenario`` validates a file and raises one-line
:class:`~lowerbase.errors.ConfigError` naming the file, the item and the problem.

The runner (``lowerbase.scenarios.runner``) samples a :class:`Trace` every ``sample_period``; the
expectations are pure functions of that trace. Times are scenario seconds from the start
(= the lower computer's first boot).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError
from lowerbase.files import read_toml
from lowerbase.firmware_model.faults import Fault, parse_fault
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.scenarios.expect import (
    Expectation,
    Moving,
    Outcome,
    PoseNear,
    Reboots,
    SocBetween,
    StateIs,
    StatusBitIs,
    Stopped,
    Trace,
)
from lowerbase.scenarios.table import Table
from lowerbase.scenarios.timeline import (
    CONTROL_ACTIONS,
    IN_PROCESS_ONLY,
    LINK_STATES,
    ROBOT_STATES,
    Action,
    Charger,
    ClearFault,
    Control,
    FaultAt,
    Initial,
    Led,
    ParamWrite,
    Pose,
    Slip,
    Twist,
    Unplug,
)

# -- the scenario ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scenario:
    name: str
    duration: float  #: [s] scenario time
    description: str = ""
    profile: Path | None = None  #: robot profile TOML (None: the packaged default)
    initial: Initial = field(default_factory=Initial)
    timeline: tuple[Action, ...] = ()
    expectations: tuple[Expectation, ...] = ()
    sample_period: float = 0.05  #: [s] trace sampling period
    source: str = "<dict>"  #: file it was loaded from
    world: Any = None  #: scenario_world.WorldSpec of a [world] table, or None

    @property
    def faults(self) -> tuple[FaultAt, ...]:
        return tuple(a for a in self.timeline if isinstance(a, FaultAt))

    def in_process_only(self) -> list[str]:
        """What this scenario needs from an in-process lower computer (empty: wire-only)."""
        needs = [f"{a.kind} at t={a.at:g} s" for a in self.timeline if a.kind in IN_PROCESS_ONLY]
        if not self.initial.pose.is_origin:
            needs.append("an initial pose other than the origin")
        if self.world is not None:
            needs.append("a [world] (it reads the emulator's ground truth)")
        return needs


# -- loading and validation --------------------------------------------------------------------

_TOP = {"scenario", "initial", "timeline", "expect", "world"}
_SCENARIO_KEYS = {"name", "description", "duration", "profile", "sample_period", "robot"}
_INITIAL_KEYS = {"soc", "x", "y", "yaw", "charger"}


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario TOML file (see docs/scenarios.md)."""
    p = Path(path)
    return scenario_from_dict(read_toml(p, "scenario"), source=str(p), base=p.parent)


def robot_of(data: Mapping[str, Any]) -> str:
    """``[scenario] robot``: "wheeled" (the default) or "legged" (scenario_legged.py)."""
    head = data.get("scenario")
    robot = head.get("robot", "wheeled") if isinstance(head, Mapping) else "wheeled"
    return robot if isinstance(robot, str) else "wheeled"


def scenario_from_dict(data: Mapping[str, Any], source: str = "<dict>",
                       base: Path | None = None) -> Scenario:
    """Build a Scenario from parsed TOML; errors start with ``source``."""
    if robot_of(data) == "legged":
        raise ConfigError(f"{source}: a legged scenario (robot = \"legged\"): load it with "
                          "load_any_scenario or run it with `lowerbase scenario run`")
    try:
        return _build(data, source, base)
    except ConfigError as e:
        raise ConfigError(f"{source}: {e}") from None


def _build(data: Mapping[str, Any], source: str, base: Path | None) -> Scenario:
    top = Table(data, "the file")
    top.done(_TOP)
    head = Table(data.get("scenario", {}), "[scenario]")
    name = head.text("name", Path(source).stem)
    duration = head.number("duration", lo=0.1, hi=3600.0, required=True)
    description = head.text("description", "")
    sample_period = head.number("sample_period", 0.05, lo=0.005, hi=1.0)
    profile_text = head.text("profile", "default")
    head.text("robot", "wheeled", choices=("wheeled", "legged"))
    head.done()
    profile: Path | None = None
    if profile_text != "default":
        profile = Path(profile_text)
        if not profile.is_absolute() and base is not None:
            profile = base / profile
        if not profile.is_file():
            raise ConfigError(f"[scenario]: profile {str(profile)!r} not found (a path "
                              "relative to the scenario file, or \"default\")")
    init = Table(data.get("initial", {}), "[initial]")
    initial = Initial(
        soc=init.number("soc", 80.0, lo=0.0, hi=100.0),
        pose=Pose(init.number("x", 0.0), init.number("y", 0.0),
                  init.number("yaw", 0.0, lo=-math.tau, hi=math.tau)),
        charger=init.flag("charger", False),
    )
    init.done()
    world = None
    if "world" in data:
        from lowerbase.scenarios.world import parse_world

        world = parse_world(data["world"], base)
    items = data.get("timeline", [])
    if not isinstance(items, list):
        raise ConfigError("timeline must be an array of tables ([[timeline]])")
    timeline = tuple(_action(item, i, duration) for i, item in enumerate(items))
    checks = data.get("expect", [])
    if not isinstance(checks, list):
        raise ConfigError("expect must be an array of tables ([[expect]])")
    expectations = tuple(_expectation(item, i, duration, world)
                         for i, item in enumerate(checks))
    return Scenario(name=name, duration=duration, description=description, profile=profile,
                    initial=initial, timeline=tuple(sorted(timeline, key=lambda a: a.at)),
                    expectations=expectations, sample_period=sample_period, source=source,
                    world=world)


def _action(item: Any, index: int, duration: float) -> Action:
    where = f"timeline[{index}]"
    t = Table(item, where)
    at = t.number("at", lo=0.0, hi=duration, required=True)
    t.where = f"timeline[{index}] (at {at:g} s)"
    if t.has("fault") and t.has("action"):
        raise ConfigError(f"{t.where}: give either action or fault, not both")
    if t.has("fault"):
        spec = t.text("fault")
        if "@" in spec:
            raise ConfigError(f"{t.where}: fault {spec!r}: give the start as at = ..., "
                              "not @T in the spec")
        try:
            fault = parse_fault(spec)
        except ConfigError as e:
            raise ConfigError(f"{t.where}: {e}") from None
        length = t.opt_number("duration", lo=0.0, hi=3600.0)
        if length is not None and fault.duration is not None:
            raise ConfigError(f"{t.where}: fault {spec!r} has a +D duration and duration too")
        if length is not None:
            fault = Fault(fault.kind, fault.arg, 0.0, length)
        t.done()
        return FaultAt(at, fault=fault)
    kind = t.text("action", choices=[
        "twist", "led", "param", "charger", "unplug", "slip", "clear_fault",
        *CONTROL_ACTIONS])
    action: Action
    if kind == "twist":
        path = t.text("path", "raw", choices=("raw", "smoothed"))
        action = Twist(at, linear=t.number("linear", 0.0, lo=-3.0, hi=3.0),
                       angular=t.number("angular", 0.0, lo=-6.0, hi=6.0),
                       duration=t.number("duration", lo=0.0, hi=3600.0, required=True),
                       smoothed=path == "smoothed", stop=t.flag("stop", True))
    elif kind == "led":
        from lowerbase.protocol.codec import default_codec

        choices = default_codec().message("LedCommand").signal("Normal").choices
        normals = {str(name): int(value) for value, name in choices.items()}
        action = Led(at, strip=t.integer_or_name("strip", 0, {"body": 0, "shelf": 1}, 0, 1),
                     submodule=t.integer_or_name("submodule", 0, {"all": 0}, 0, 8),
                     urgency=0xFF if t.flag("maintenance", False) else 0,
                     abnormal=0xFF if t.flag("failure", False) else 0,
                     normal=t.integer_or_name("normal", 0xA3, normals, 0, 255),
                     color=t.integer_or_name("color", 0xFFFFFF, {}, 0, 0xFFFFFF))
    elif kind == "param":
        from lowerbase.firmware_model.parameters import SPECS

        names = [s.name for s in SPECS.values()]
        action = ParamWrite(at, name=t.text("name", choices=names),
                            value=t.number("value", required=True))
    elif kind == "charger":
        action = Charger(at, connected=t.flag("connected", True))
    elif kind == "unplug":
        action = Unplug(at, duration=t.number("duration", lo=0.0, hi=3600.0, required=True))
    elif kind == "slip":
        action = Slip(at, wheel=t.text("wheel", "left", choices=("left", "right", "both")),
                      fraction=t.number("fraction", 0.5, lo=0.0, hi=1.0),
                      duration=t.number("duration", lo=0.0, hi=3600.0, required=True))
    elif kind == "clear_fault":
        from lowerbase.firmware_model.faults import KINDS

        which = t.text("kind", "all", choices=["all", *KINDS])
        action = ClearFault(at, fault_kind=None if which == "all" else which)
    else:
        action = Control(at, command=CONTROL_ACTIONS[kind], name=kind)
    t.done()
    return action


def _bit(t: Table) -> StatusBit:
    value = t._get("bit")
    if isinstance(value, str):
        try:
            return StatusBit[value]
        except KeyError:
            names = [str(b.name) for b in StatusBit]
            close = difflib.get_close_matches(value, names, n=1)
            hint = f"did you mean {close[0]}?" if close else "see docs/status-codes.md"
            raise ConfigError(f"{t.where}: unknown StatusCode bit {value!r}; {hint}") from None
    if isinstance(value, int) and not isinstance(value, bool):
        for b in StatusBit:
            if int(b) == 1 << value:
                return b
        raise ConfigError(f"{t.where}: StatusCode bit {value} is reserved")
    raise ConfigError(f"{t.where}: bit must be a StatusCode bit name (e.g. WATCHDOG_STOP) "
                      f"or number, not {value!r}")


def _at_or_during(t: Table, duration: float) -> tuple[float | None, tuple[float, float] | None,
                                                       bool]:
    at = t.opt_number("at", lo=0.0, hi=duration)
    during = t.interval("during")
    sometime = False
    if during is None and t.has("sometime"):
        during, sometime = t.interval("sometime"), True
    if at is not None and during is not None:
        raise ConfigError(f"{t.where}: give at, during or sometime, not several")
    return at, during, sometime


def _expectation(item: Any, index: int, duration: float, world: Any = None) -> Expectation:
    t = Table(item, f"expect[{index}]")
    kind = t.text("kind", choices=("stopped", "moving", "status", "pose", "soc", "state",
                                   "link", "reboots", "localization", "contact"))
    t.where = f"expect[{index}] ({kind})"
    name = t.text("name", "")
    sources = ("truth", "measured")
    exp: Expectation
    if kind in ("localization", "contact"):
        from lowerbase.scenarios.world import make_expectation

        exp = make_expectation(kind, t, name, duration, world)
    elif kind == "stopped":
        exp = Stopped(name, after=t.number("after", lo=0.0, hi=duration, required=True),
                      within=t.number("within", lo=0.0, hi=3600.0, required=True),
                      until=t.opt_number("until", lo=0.0, hi=duration),
                      speed=t.number("speed", 0.02, lo=0.0), turn_rate=t.number(
                          "turn_rate", 0.05, lo=0.0), source=t.text("source", "truth",
                                                                     choices=sources))
    elif kind == "moving":
        during = t.interval("during")
        if during is None:
            raise ConfigError(f"{t.where}: missing during = [start, end]")
        exp = Moving(name, during=during, speed=t.number("speed", 0.05, lo=0.0),
                     turn_rate=t.number("turn_rate", math.inf, lo=0.0),
                     source=t.text("source", "truth", choices=sources))
    elif kind == "status":
        bit = _bit(t)
        at, during, sometime = _at_or_during(t, duration)
        exp = StatusBitIs(name, bit=bit, set=t.flag("set", True), at=at, during=during,
                          sometime=sometime)
    elif kind == "pose":
        within = t.number("within", math.inf, lo=0.0)
        beyond = t.number("beyond", 0.0, lo=0.0)
        if not any(t.has(k) for k in ("within", "beyond", "yaw_within")):
            raise ConfigError(f"{t.where}: give within or beyond [m], or yaw_within [rad]")
        exp = PoseNear(name, estimate=t.text("estimate", "odom", choices=("odom", "odom_raw")),
                       within=within, beyond=beyond,
                       yaw_within=t.opt_number("yaw_within", lo=0.0),
                       at=t.opt_number("at", lo=0.0, hi=duration))
    elif kind == "soc":
        low, high = t.number("min", 0.0, lo=0.0, hi=100.0), t.number("max", 100.0, lo=0.0,
                                                                        hi=100.0)
        if low > high:
            raise ConfigError(f"{t.where}: min {low:g} > max {high:g}")
        exp = SocBetween(name, low=low, high=high, at=t.opt_number("at", lo=0.0, hi=duration),
                         source=t.text("source", "reported", choices=("reported", "pack")))
    elif kind in ("state", "link"):
        at, during, sometime = _at_or_during(t, duration)
        if sometime:
            raise ConfigError(f"{t.where}: use at or during")
        names = ROBOT_STATES if kind == "state" else LINK_STATES
        exp = StateIs(name, equals=t.text("equals", choices=names),
                      what="robot" if kind == "state" else "link", at=at, during=during)
    else:
        exp = Reboots(name, equals=int(t.number("equals", lo=0, hi=65535, required=True)))
    t.done()
    return exp


def iter_outcomes(scenario: Scenario, trace: Trace) -> Iterator[tuple[Expectation, Outcome]]:
    for exp in scenario.expectations:
        yield exp, exp.evaluate(trace)
