"""What a wheeled scenario run is checked on: the sampled :class:`Trace` (a column per signal)
and the expectations, pure functions of that trace returning an :class:`Outcome`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from lowerbase.protocol.status_codes import StatusBit, describe
from lowerbase.scenarios.timeline import LINK_STATES, ROBOT_STATES

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
