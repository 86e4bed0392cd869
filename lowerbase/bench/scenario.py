"""Scenarios: a run of the chassis described in a TOML file, and the checks made on it.

A scenario names a profile, the initial state (SOC, pose, charger), a timeline of actions (what
the upper computer or the world does: twist segments, LED commands, parameter writes, e-stop,
charger, lower-computer reboot, ...) and of faults (``lowerbase.firmware_model.faults`` specs),
and expectations ("stopped within 0.6 s of t = 5", "WATCHDOG_STOP set during [6, 8]", "/odom
within 0.05 m of the truth at the end", "SOC between 79 and 80"). docs/scenarios.md is the
reference of the file format; ``load_scenario`` validates a file and raises one-line
:class:`~lowerbase.errors.ConfigError` naming the file, the item and the problem.

The runner (``lowerbase.bench.runner``) samples a :class:`Trace` every ``sample_period``; the
expectations are pure functions of that trace. Times are scenario seconds from the start
(= the lower computer's first boot).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from lowerbase.errors import ConfigError
from lowerbase.files import read_toml
from lowerbase.firmware_model.faults import Fault, parse_fault
from lowerbase.protocol.status_codes import StatusBit, describe

if TYPE_CHECKING:
    from lowerbase.bench.scenario_legged import LeggedScenario
    from lowerbase.bench.scenario_tasks import TasksScenario

#: RobotState value table of SystemStatus (chassis.dbc)
ROBOT_STATES = ("Boot", "Standby", "Active", "EmergencyStop", "Fault")
#: DriverCore LinkState values
LINK_STATES = ("waiting", "configuring", "ready", "lost", "standby")
#: ControlCommand actions: scenario action name -> ControlCommand value name
CONTROL_ACTIONS = {
    "enable": "EnableCanControl",
    "standby": "Standby",
    "estop": "EStopSet",
    "estop_release": "EStopRelease",
    "fault_clear": "FaultClear",
    "odometer_reset": "OdometerReset",
    "reboot": "Reboot",
}
#: actions that reach into the emulated lower computer, not through the wire
IN_PROCESS_ONLY = ("charger", "slip", "clear_fault")
TWIST_PERIOD = 0.05  #: [s] twists are published at 20 Hz during a segment, as a nav stack does


# -- the model ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Pose:
    x: float = 0.0  #: [m]
    y: float = 0.0  #: [m]
    yaw: float = 0.0  #: [rad]

    @property
    def is_origin(self) -> bool:
        return self.x == 0.0 and self.y == 0.0 and self.yaw == 0.0


@dataclass(frozen=True)
class Initial:
    soc: float = 80.0  #: [%] 0..100, state of charge of the pack at power-on
    pose: Pose = field(default_factory=Pose)  #: true pose at power-on (odometry starts there)
    charger: bool = False  #: charger connected at power-on


@dataclass(frozen=True)
class Action:
    """Something that happens at ``at`` [s]. Subclasses carry the kind's arguments."""

    at: float
    kind: ClassVar[str] = ""

    def label(self) -> str:
        """Short text for plots and logs."""
        return self.kind

    @property
    def end(self) -> float:
        """[s] when the action's effect ends (= ``at`` for instantaneous ones)."""
        return self.at


@dataclass(frozen=True)
class Twist(Action):
    """Publish (linear [m/s], angular [rad/s]) at 20 Hz for ``duration`` [s]."""

    linear: float = 0.0
    angular: float = 0.0
    duration: float = 1.0
    smoothed: bool = False  #: True: /smooth_cmd_vel (Mode Smoothed), False: /base_cmd_vel (Raw)
    stop: bool = True  #: publish one zero twist at the end (a nav stack reaching its goal)
    kind: ClassVar[str] = "twist"

    def label(self) -> str:
        return f"twist {self.linear:g} m/s {self.angular:g} rad/s"

    @property
    def end(self) -> float:
        return self.at + self.duration


@dataclass(frozen=True)
class Led(Action):
    strip: int = 0  #: 0 body (rgbled), 1 shelf (rgbled_shelf)
    submodule: int = 0  #: 0 all, 1..8 one
    urgency: int = 0
    abnormal: int = 0
    normal: int = 0xA3  #: LedCommand Normal value (0xA3 Idle)
    color: int = 0xFFFFFF
    kind: ClassVar[str] = "led"

    def label(self) -> str:
        return f"LED #{self.color:06X}"


@dataclass(frozen=True)
class ParamWrite(Action):
    name: str = ""  #: woosh parameter name (commandTimeout, maxLinear, ...)
    value: float = 0.0
    kind: ClassVar[str] = "param"

    def label(self) -> str:
        return f"{self.name}={self.value:g}"


@dataclass(frozen=True)
class Control(Action):
    """A ControlCommand (enable, standby, estop, estop_release, fault_clear, ...)."""

    command: str = "EnableCanControl"  #: ControlCommand value name
    name: str = "enable"  #: the scenario's action name
    kind: ClassVar[str] = "control"

    def label(self) -> str:
        return self.name


@dataclass(frozen=True)
class Charger(Action):
    connected: bool = True
    kind: ClassVar[str] = "charger"

    def label(self) -> str:
        return "charger on" if self.connected else "charger off"


@dataclass(frozen=True)
class Unplug(Action):
    """Frames from the upper computer stop reaching the lower one for ``duration`` [s]."""

    duration: float = 1.0
    kind: ClassVar[str] = "unplug"

    @property
    def end(self) -> float:
        return self.at + self.duration


@dataclass(frozen=True)
class Slip(Action):
    """A wheel slips: ground speed = (1 - fraction) x rim speed for ``duration`` [s]."""

    wheel: str = "left"  #: left, right or both
    fraction: float = 0.5
    duration: float = 1.0
    kind: ClassVar[str] = "slip"

    def label(self) -> str:
        return f"slip {self.wheel} {self.fraction:g}"

    @property
    def end(self) -> float:
        return self.at + self.duration


@dataclass(frozen=True)
class FaultAt(Action):
    """Inject ``fault`` (its ``start`` unused) at ``at`` for its duration (None: to the end)."""

    fault: Fault = field(default_factory=lambda: Fault("silence"))
    kind: ClassVar[str] = "fault"

    def label(self) -> str:
        return str(self.fault)

    @property
    def end(self) -> float:
        return self.at + (self.fault.duration if self.fault.duration is not None else math.inf)

    def spec_from_boot(self) -> str:
        """The fault as ``lowerbase emulate --fault`` takes it (times from boot)."""
        return str(Fault(self.fault.kind, self.fault.arg, self.at or 1e-3, self.fault.duration))


@dataclass(frozen=True)
class ClearFault(Action):
    fault_kind: str | None = None  #: None: every injected fault
    kind: ClassVar[str] = "clear_fault"

    def label(self) -> str:
        return f"clear {self.fault_kind or 'faults'}"


# -- the trace ---------------------------------------------------------------------------------

#: columns of a Trace, with units; NaN where a value is not known (no truth over a bus, ...)
COLUMNS: dict[str, str] = {
    "t": "s",
    "truth_x": "m", "truth_y": "m", "truth_yaw": "rad", "truth_v": "m/s", "truth_w": "rad/s",
    "raw_x": "m", "raw_y": "m", "raw_yaw": "rad",  # /odom_raw (wheel odometry)
    "ekf_x": "m", "ekf_y": "m", "ekf_yaw": "rad",  # /odom (EKF)
    "meas_v": "m/s", "meas_w": "rad/s",  # MotionState (measured twist)
    "cmd_v": "m/s", "cmd_w": "rad/s",  # the twist the scenario publishes
    "soc": "%", "pack_soc": "%", "voltage": "V", "current": "A",
    "capacity_soc": "%",  # BmsCapacity remain/full: the model's SOC in 0.01 Ah steps
    "status": "",  # StatusCode as the driver received it
    "robot_state": "",  # SystemStatus RobotState (-1 until received)
    "link": "",  # index into LINK_STATES
    "reboots": "",  # reboots the driver has seen
    # with a [world] (scenario_world.py): movebase_pose2d, its error against the truth, and
    # the contact bit mask (bit i: WorldSpec.contact_names[i])
    "amcl_x": "m", "amcl_y": "m", "amcl_yaw": "rad", "amcl_error": "m", "amcl_yaw_error": "rad",
    "contact": "",
}


_COLUMN_INDEX = {name: i for i, name in enumerate(COLUMNS)}


class Trace:
    """Samples of a run, column by column (see :data:`COLUMNS`).

    Stored in one preallocated float array (rows x columns, grown by doubling); a column is a
    view of it, with no list-to-array conversion per read."""

    def __init__(self, capacity: int = 1024) -> None:
        self._data = np.full((max(1, capacity), len(COLUMNS)), math.nan)
        self._n = 0

    def append(self, sample: Mapping[str, float]) -> None:
        if self._n == len(self._data):
            grown = np.full((2 * len(self._data), len(COLUMNS)), math.nan)
            grown[: self._n] = self._data
            self._data = grown
        row = self._data[self._n]
        for name, value in sample.items():
            i = _COLUMN_INDEX.get(name)
            if i is not None:
                row[i] = value
        self._n += 1

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, name: str) -> np.ndarray:
        column: np.ndarray = self._data[: self._n, _COLUMN_INDEX[name]]
        return column

    @property
    def end(self) -> float:
        return float(self["t"][-1]) if len(self) else 0.0

    def index_at(self, t: float) -> int:
        """Index of the last sample at or before ``t`` [s] (the first one if none)."""
        i = int(np.searchsorted(self["t"], t + 1e-9, side="right")) - 1
        return max(i, 0)

    def window(self, t0: float, t1: float) -> np.ndarray:
        """Boolean mask of the samples with ``t0 <= t <= t1``."""
        t = self["t"]
        mask: np.ndarray = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
        return mask

    def has(self, name: str) -> bool:
        """True when column ``name`` has at least one known (finite) value."""
        return bool(len(self)) and bool(np.isfinite(self[name]).any())

    def as_dict(self) -> dict[str, list[float]]:
        return {name: self._data[: self._n, i].tolist() for name, i in _COLUMN_INDEX.items()}


# -- expectations ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Outcome:
    status: str  #: "passed", "failed" or "skipped"
    detail: str

    @property
    def passed(self) -> bool:
        return self.status != "failed"


@dataclass(frozen=True)
class Expectation:
    """One check on the trace; ``evaluate`` is pure. ``name`` is the scenario's text, if any."""

    name: str = ""
    kind: ClassVar[str] = ""

    def describe(self) -> str:
        raise NotImplementedError

    def title(self) -> str:
        return self.name or self.describe()

    def evaluate(self, trace: Trace) -> Outcome:
        raise NotImplementedError


def _end_or(t: float | None, trace: Trace) -> float:
    return trace.end if t is None else t


def _fmt_t(t: float | None) -> str:
    return "the end" if t is None else f"t={t:g} s"


def _speed_columns(trace: Trace, source: str) -> tuple[np.ndarray, np.ndarray, str]:
    if source == "truth" and not trace.has("truth_v"):
        source = "measured"  # over a bus the truth may be unknown: what the wheels report
    if source == "truth":
        return trace["truth_v"], trace["truth_w"], "true"
    return trace["meas_v"], trace["meas_w"], "measured"


@dataclass(frozen=True)
class Stopped(Expectation):
    """|v| < speed and |w| < turn_rate from ``after + within`` until ``until`` (end)."""

    after: float = 0.0  #: [s] the event's time
    within: float = 0.6  #: [s] allowed stopping time
    until: float | None = None  #: [s] None: to the end of the run
    speed: float = 0.02  #: [m/s]
    turn_rate: float = 0.05  #: [rad/s]
    source: str = "truth"  #: truth or measured (MotionState)
    kind: ClassVar[str] = "stopped"

    def describe(self) -> str:
        return f"stopped within {self.within:g} s of t={self.after:g} s"

    def evaluate(self, trace: Trace) -> Outcome:
        v, w, what = _speed_columns(trace, self.source)
        until = _end_or(self.until, trace)
        if until < self.after + self.within or trace.end < self.after + self.within:
            return Outcome("failed", "the run ended before the deadline")
        moving = (np.abs(v) >= self.speed) | (np.abs(w) >= self.turn_rate)
        after = trace.window(self.after, until)
        late = after & moving & (trace["t"] > self.after + self.within + 1e-9)
        idx = np.flatnonzero(after & moving)
        settle = trace["t"][idx[-1]] - self.after if len(idx) else 0.0
        if late.any():
            i = int(np.flatnonzero(late)[0])
            return Outcome("failed", f"still moving at t={trace['t'][i]:.2f} s "
                           f"({what} |v|={abs(v[i]):.3f} m/s, |w|={abs(w[i]):.3f} rad/s)")
        return Outcome("passed", f"{what} speed below {self.speed:g} m/s "
                       f"{max(settle, 0.0):.2f} s after t={self.after:g} s")


@dataclass(frozen=True)
class Moving(Expectation):
    """|v| or |w| reaches ``speed`` / ``turn_rate`` at some time within ``during``."""

    during: tuple[float, float] = (0.0, 0.0)
    speed: float = 0.05  #: [m/s]
    turn_rate: float = math.inf  #: [rad/s]
    source: str = "truth"
    kind: ClassVar[str] = "moving"

    def describe(self) -> str:
        return f"moving at >= {self.speed:g} m/s during [{self.during[0]:g}, {self.during[1]:g}] s"

    def evaluate(self, trace: Trace) -> Outcome:
        v, w, what = _speed_columns(trace, self.source)
        mask = trace.window(*self.during)
        if not mask.any():
            return Outcome("failed", "no samples in the window")
        top_v, top_w = float(np.max(np.abs(v[mask]))), float(np.max(np.abs(w[mask])))
        ok = top_v >= self.speed or top_w >= self.turn_rate
        return Outcome("passed" if ok else "failed",
                       f"top {what} speed {top_v:.3f} m/s, {top_w:.3f} rad/s")


def _window_text(at: float | None, during: tuple[float, float] | None, sometime: bool) -> str:
    if during is not None:
        return f"{'at some time ' if sometime else ''}during [{during[0]:g}, {during[1]:g}] s"
    return f"at {_fmt_t(at)}"


def _select(trace: Trace, at: float | None, during: tuple[float, float] | None) -> np.ndarray:
    if during is not None:
        return trace.window(*during)
    mask = np.zeros(len(trace), dtype=bool)
    if len(trace):
        mask[trace.index_at(_end_or(at, trace))] = True
    return mask


@dataclass(frozen=True)
class StatusBitIs(Expectation):
    """StatusCode bit ``bit`` set (or clear) at ``at``, during ``during`` or sometime in it."""

    bit: StatusBit = StatusBit.ESTOP_BUTTON
    set: bool = True
    at: float | None = None
    during: tuple[float, float] | None = None
    sometime: bool = False  #: during: at least one sample instead of every sample
    kind: ClassVar[str] = "status"

    def describe(self) -> str:
        return (f"StatusCode {self.bit.name} {'set' if self.set else 'clear'} "
                f"{_window_text(self.at, self.during, self.sometime)}")

    def evaluate(self, trace: Trace) -> Outcome:
        mask = _select(trace, self.at, self.during)
        if not mask.any():
            return Outcome("failed", "no samples in the window")
        codes = trace["status"][mask].astype(np.int64)
        hit = ((codes & int(self.bit)) != 0) == self.set
        ok = bool(hit.any() if self.sometime else hit.all())
        times = trace["t"][mask]
        if ok:
            first = float(times[int(np.argmax(hit))])
            return Outcome("passed", f"{'seen' if self.sometime else 'holds'} from t={first:.2f} s")
        bad = int(np.argmin(hit))
        return Outcome("failed", f"at t={times[bad]:.2f} s StatusCode = "
                       f"{', '.join(describe(int(codes[bad]))) or '0'}")


@dataclass(frozen=True)
class PoseNear(Expectation):
    """An estimate (odom_raw or odom) within ``within`` [m] (and ``beyond`` at least) of the
    truth at ``at`` (end); optionally the heading within ``yaw_within`` [rad]."""

    estimate: str = "odom"  #: odom_raw (wheel odometry) or odom (EKF)
    within: float = math.inf
    beyond: float = 0.0
    yaw_within: float | None = None
    at: float | None = None
    kind: ClassVar[str] = "pose"

    def describe(self) -> str:
        bounds = []
        if math.isfinite(self.within):
            bounds.append(f"within {self.within:g} m")
        if self.beyond:
            bounds.append(f"at least {self.beyond:g} m away")
        if self.yaw_within is not None:
            bounds.append(f"heading within {self.yaw_within:g} rad")
        return f"/{self.estimate} {' and '.join(bounds)} of the truth at {_fmt_t(self.at)}"

    def evaluate(self, trace: Trace) -> Outcome:
        if not trace.has("truth_x"):
            return Outcome("skipped", "no ground truth in this run")
        i = trace.index_at(_end_or(self.at, trace))
        prefix = "raw" if self.estimate == "odom_raw" else "ekf"
        ex, ey, eyaw = (trace[f"{prefix}_{c}"][i] for c in ("x", "y", "yaw"))
        if not math.isfinite(ex):
            return Outcome("failed", f"/{self.estimate} not running at t={trace['t'][i]:.2f} s")
        err = math.hypot(ex - trace["truth_x"][i], ey - trace["truth_y"][i])
        yaw_err = abs(math.remainder(eyaw - trace["truth_yaw"][i], math.tau))
        ok = self.beyond <= err <= self.within
        if self.yaw_within is not None:
            ok = ok and yaw_err <= self.yaw_within
        return Outcome("passed" if ok else "failed",
                       f"error {err:.3f} m, heading {yaw_err:.4f} rad at t={trace['t'][i]:.2f} s")


@dataclass(frozen=True)
class SocBetween(Expectation):
    low: float = 0.0  #: [%]
    high: float = 100.0  #: [%]
    at: float | None = None
    source: str = "reported"  #: reported (BmsPack Soc, integer %) or pack (the model's, exact)
    kind: ClassVar[str] = "soc"

    def describe(self) -> str:
        return f"{self.source} SOC between {self.low:g} and {self.high:g} % at {_fmt_t(self.at)}"

    def evaluate(self, trace: Trace) -> Outcome:
        column = "soc" if self.source == "reported" else "pack_soc"
        if not trace.has(column):
            if self.source == "pack":
                return Outcome("skipped", "the pack model is not in this process")
            return Outcome("failed", "no BmsPack frame received")
        i = trace.index_at(_end_or(self.at, trace))
        soc = float(trace[column][i])
        ok = self.low <= soc <= self.high
        return Outcome("passed" if ok else "failed", f"SOC {soc:.3f} % at t={trace['t'][i]:.2f} s")


@dataclass(frozen=True)
class StateIs(Expectation):
    """SystemStatus RobotState (``what = "robot"``) or the driver link state (``"link"``)."""

    equals: str = "Active"
    what: str = "robot"
    at: float | None = None
    during: tuple[float, float] | None = None
    kind: ClassVar[str] = "state"

    def describe(self) -> str:
        who = "robot state" if self.what == "robot" else "driver link"
        return f"{who} {self.equals} {_window_text(self.at, self.during, False)}"

    def evaluate(self, trace: Trace) -> Outcome:
        mask = _select(trace, self.at, self.during)
        if not mask.any():
            return Outcome("failed", "no samples in the window")
        names = ROBOT_STATES if self.what == "robot" else LINK_STATES
        column = "robot_state" if self.what == "robot" else "link"
        values = trace[column][mask]
        want = names.index(self.equals)
        ok = values == want
        if ok.all():
            return Outcome("passed", f"{self.equals} in {int(mask.sum())} sample(s)")
        bad = int(np.argmin(ok))
        v = int(values[bad])
        seen = names[v] if 0 <= v < len(names) else "unknown"
        return Outcome("failed", f"{seen} at t={trace['t'][mask][bad]:.2f} s")


@dataclass(frozen=True)
class Reboots(Expectation):
    equals: int = 0  #: reboots the driver saw (Heartbeat BootCounter changes) by the end
    kind: ClassVar[str] = "reboots"

    def describe(self) -> str:
        return f"the driver saw {self.equals} reboot(s)"

    def evaluate(self, trace: Trace) -> Outcome:
        seen = int(trace["reboots"][-1]) if len(trace) else 0
        return Outcome("passed" if seen == self.equals else "failed", f"{seen} seen")


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


class _Table:
    """A TOML table being validated: typed getters, unknown keys reported with a suggestion."""

    def __init__(self, data: Any, where: str) -> None:
        if not isinstance(data, Mapping):
            raise ConfigError(f"{where} must be a table, not {data!r}")
        self.data = data
        self.where = where
        self.used: set[str] = set()

    def _get(self, key: str) -> Any:
        self.used.add(key)
        return self.data.get(key)

    def has(self, key: str) -> bool:
        return key in self.data

    def number(self, key: str, default: float | None = None, *, lo: float = -math.inf,
               hi: float = math.inf, required: bool = False) -> float:
        value = self._get(key)
        if value is None:
            if required or default is None:
                raise ConfigError(f"{self.where}: missing {key}")
            return default
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{self.where}: {key} must be a number, not {value!r}")
        if not (math.isfinite(value) and lo <= value <= hi):
            raise ConfigError(f"{self.where}: {key} = {value!r} is outside {lo:g}..{hi:g}")
        return float(value)

    def opt_number(self, key: str, *, lo: float = -math.inf, hi: float = math.inf
                   ) -> float | None:
        return self.number(key, lo=lo, hi=hi) if self.has(key) else None

    def text(self, key: str, default: str | None = None, *,
             choices: Sequence[str] | None = None) -> str:
        value = self._get(key)
        if value is None:
            if default is None:
                raise ConfigError(f"{self.where}: missing {key}")
            return default
        if not isinstance(value, str):
            raise ConfigError(f"{self.where}: {key} must be a string, not {value!r}")
        if choices is not None and value not in choices:
            close = difflib.get_close_matches(value, list(choices), n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"one of: {', '.join(choices)}"
            raise ConfigError(f"{self.where}: {key} = {value!r} is not known; {hint}")
        return value

    def flag(self, key: str, default: bool) -> bool:
        value = self._get(key)
        if value is None:
            return default
        if not isinstance(value, bool):
            raise ConfigError(f"{self.where}: {key} must be true or false, not {value!r}")
        return value

    def interval(self, key: str) -> tuple[float, float] | None:
        value = self._get(key)
        if value is None:
            return None
        if (not isinstance(value, list) or len(value) != 2 or any(
                isinstance(v, bool) or not isinstance(v, int | float) for v in value)
                or not value[0] <= value[1]):
            raise ConfigError(f"{self.where}: {key} must be [start, end] in seconds with "
                              f"start <= end, not {value!r}")
        return float(value[0]), float(value[1])

    def integer_or_name(self, key: str, default: int, names: Mapping[str, int],
                        lo: int, hi: int) -> int:
        value = self._get(key)
        if value is None:
            return default
        if isinstance(value, str):
            lookup = {k.lower(): v for k, v in names.items()}
            if value.lower() in lookup:
                return lookup[value.lower()]
            if value.startswith("#") and len(value) == 7:
                try:
                    return int(value[1:], 16)
                except ValueError:
                    pass
            raise ConfigError(f"{self.where}: {key} = {value!r} is not known; "
                              f"one of: {', '.join(names) or 'a number'}")
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise ConfigError(f"{self.where}: {key} must be an integer {lo}..{hi}, not {value!r}")
        return value

    def done(self, allowed: set[str] | None = None) -> None:
        """Reject keys nobody asked for."""
        known = sorted(allowed if allowed is not None else self.used)
        for key in self.data:
            if key not in known:
                close = difflib.get_close_matches(key, known, n=1)
                hint = f"; did you mean {close[0]}?" if close else f"; known: {', '.join(known)}"
                raise ConfigError(f"{self.where}: unknown key {key!r}{hint}")


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario TOML file (see docs/scenarios.md)."""
    p = Path(path)
    return scenario_from_dict(read_toml(p, "scenario"), source=str(p), base=p.parent)


def robot_of(data: Mapping[str, Any]) -> str:
    """``[scenario] robot``: "wheeled" (the default) or "legged" (scenario_legged.py)."""
    head = data.get("scenario")
    robot = head.get("robot", "wheeled") if isinstance(head, Mapping) else "wheeled"
    return robot if isinstance(robot, str) else "wheeled"


def load_any_scenario(path: str | Path) -> Scenario | LeggedScenario | TasksScenario:
    """A wheeled, a legged (``robot = "legged"``) or a task (a ``[tasks]`` table,
    scenario_tasks.py) scenario file."""
    p = Path(path)
    data = read_toml(p, "scenario")
    if "tasks" in data:
        from lowerbase.bench.scenario_tasks import load_tasks_scenario

        try:
            return load_tasks_scenario(p)
        except ConfigError as e:
            raise ConfigError(str(e) if str(e).startswith(str(p)) else f"{p}: {e}") from None
    if robot_of(data) == "legged":
        from lowerbase.bench.scenario_legged import legged_scenario_from_dict

        return legged_scenario_from_dict(data, source=str(p), base=p.parent)
    return scenario_from_dict(data, source=str(p), base=p.parent)


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
    top = _Table(data, "the file")
    top.done(_TOP)
    head = _Table(data.get("scenario", {}), "[scenario]")
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
    init = _Table(data.get("initial", {}), "[initial]")
    initial = Initial(
        soc=init.number("soc", 80.0, lo=0.0, hi=100.0),
        pose=Pose(init.number("x", 0.0), init.number("y", 0.0),
                  init.number("yaw", 0.0, lo=-math.tau, hi=math.tau)),
        charger=init.flag("charger", False),
    )
    init.done()
    world = None
    if "world" in data:
        from lowerbase.bench.scenario_world import parse_world

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
    t = _Table(item, where)
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


def _bit(t: _Table) -> StatusBit:
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


def _at_or_during(t: _Table, duration: float) -> tuple[float | None, tuple[float, float] | None,
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
    t = _Table(item, f"expect[{index}]")
    kind = t.text("kind", choices=("stopped", "moving", "status", "pose", "soc", "state",
                                   "link", "reboots", "localization", "contact"))
    t.where = f"expect[{index}] ({kind})"
    name = t.text("name", "")
    sources = ("truth", "measured")
    exp: Expectation
    if kind in ("localization", "contact"):
        from lowerbase.bench.scenario_world import make_expectation

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


# -- the library -------------------------------------------------------------------------------


def library_dirs() -> list[Path]:
    """Where library scenarios live: the repository's scenarios/ (a checkout or an editable
    install), then the copy packaged in lowerbase/bench/scenarios/."""
    here = Path(__file__).resolve()
    dirs = [here.parents[2] / "scenarios", here.parent / "scenarios"]
    return [d for d in dirs if d.is_dir()]


#: sub-libraries (scenarios/NAME/*.toml, named "NAME/STEM") that `library("all")` includes
SUBLIBRARIES = ("tasks",)


def library(robot: str = "wheeled") -> dict[str, Path]:
    """Library scenarios of ``robot`` ("wheeled", "legged" or "all") by name (file stem); the
    repository's copy wins. "all" also has the sub-libraries' scenarios, as "tasks/STEM"."""
    found: dict[str, Path] = {}
    for d in reversed(library_dirs()):
        for p in sorted(d.glob("*.toml")):
            found[p.stem] = p
        if robot == "all":
            for sub in SUBLIBRARIES:
                for p in sorted((d / sub).glob("*.toml")):
                    found[f"{sub}/{p.stem}"] = p
    if robot != "all":
        found = {k: p for k, p in found.items() if _robot_of_file(p) == robot}
    return dict(sorted(found.items()))


def _robot_of_file(path: Path) -> str:
    try:
        return robot_of(read_toml(path, "scenario"))
    except ConfigError:
        return "wheeled"  # loading it says what is wrong


def find_scenario(name_or_path: str) -> Path:
    """A scenario file by path, or a library scenario by name."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    lib = library("all")
    if name_or_path in lib:
        return lib[name_or_path]
    if p.suffix or "/" in name_or_path:
        raise ConfigError(f"no such scenario file: {p}")
    close = difflib.get_close_matches(name_or_path, list(lib), n=1)
    hint = f"did you mean {close[0]}?" if close else f"library: {', '.join(lib) or 'empty'}"
    raise ConfigError(f"no scenario file or library scenario {name_or_path!r}; {hint}")


def iter_outcomes(scenario: Scenario, trace: Trace) -> Iterator[tuple[Expectation, Outcome]]:
    for exp in scenario.expectations:
        yield exp, exp.evaluate(trace)
