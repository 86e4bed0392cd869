"""The campaign file: ``[campaign]``, ``[vary]``, ``[[timeline]]``, ``[[expect]]``,
``[report]`` (docs/campaigns.md), validated into a frozen :class:`Campaign`."""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lowerbase.errors import CampaignError, ConfigError
from lowerbase.files import read_toml

KINDS = ("wheeled", "legged", "tasks", "trace")
#: each kind's metric columns in a run's row (campaign/execute.py fills them where the run has
#: the data; tests/campaign/test_kinds.py checks a row has no other), and a run's wall time
METRICS: dict[str, tuple[str, ...]] = {
    "wheeled": ("sim_s", "odom_error_m", "odom_error_p95_m", "odom_raw_error_m",
                "odom_raw_error_p95_m", "odom_yaw_error_rad", "soc_final", "reboots"),
    "tasks": ("sim_s", "localization_error_m", "localization_error_p95_m", "soc_final",
              "driven_m", "task_time_s"),
    "legged": ("sim_s", "position_error_m", "position_error_p95_m", "voltage_final"),
    "trace": ("sim_s",),
}
WALL_METRIC = "wall_s"
DISTRIBUTIONS = ("values", "uniform", "normal", "integers")
_CAMPAIGN_KEYS = ("name", "description", "scenario", "scenarios", "runs", "grid", "seed",
                  "reseed", "keep_expect")
_REPORT_KEYS = ("metric", "threshold")
_TOP = ("campaign", "vary", "timeline", "expect", "report")
MAX_RUNS = 1_000_000


def _unknown(where: str, keys: Any, known: tuple[str, ...]) -> None:
    for key in keys:
        if key not in known:
            close = difflib.get_close_matches(str(key), known, n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"known: {', '.join(known)}"
            raise CampaignError(f"{where}: unknown key {key!r}; {hint}")


def _is_number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)


@dataclass(frozen=True)
class Variation:
    """One varied value: ``key`` is a dotted path into the scenario (``initial.soc``,
    ``timeline.2.at``) or its profile (``profile.truth.left_radius_error``)."""

    key: str
    dist: str  #: one of DISTRIBUTIONS
    values: tuple[Any, ...] = ()  #: ``values``: the list (a grid axis with grid = true)
    low: float = -math.inf  #: ``uniform``/``integers``: the range; ``normal``: the clip
    high: float = math.inf
    mean: float = 0.0  #: ``normal``
    sd: float = 0.0

    def is_axis(self, grid: bool) -> bool:
        return grid and self.dist == "values"

    def sample(self, rng: np.random.Generator) -> Any:
        if self.dist == "values":
            return self.values[int(rng.integers(len(self.values)))]
        if self.dist == "uniform":
            return float(rng.uniform(self.low, self.high))
        if self.dist == "integers":
            return int(rng.integers(int(self.low), int(self.high) + 1))
        return float(np.clip(rng.normal(self.mean, self.sd), self.low, self.high))

    def describe(self) -> str:
        if self.dist == "values":
            return f"one of {list(self.values)}"
        if self.dist == "normal":
            clip = "" if (self.low, self.high) == (-math.inf, math.inf) else \
                f" clipped to [{self.low:g}, {self.high:g}]"
            return f"normal(mean {self.mean:g}, sd {self.sd:g}){clip}"
        return f"{self.dist} [{self.low:g}, {self.high:g}]"


def parse_variation(key: str, raw: Any) -> Variation:
    where = f"[vary] {key!r}"
    if not key or any(not part for part in key.split(".")):
        raise CampaignError(f"{where}: a key is a dotted path such as \"initial.soc\"")
    if isinstance(raw, list):
        raw = {"values": raw}
    elif not isinstance(raw, Mapping):
        raw = {"values": [raw]}  # a fixed value
    dists = [d for d in DISTRIBUTIONS if d in raw]
    if len(dists) != 1:
        raise CampaignError(f"{where}: give exactly one of {', '.join(DISTRIBUTIONS)} "
                            "(or a bare list of values)")
    dist = dists[0]
    _unknown(where, raw, (dist, "min", "max") if dist == "normal" else (dist,))
    arg = raw[dist]
    if dist == "values":
        if not isinstance(arg, list) or not arg:
            raise CampaignError(f"{where}: values must be a non-empty list")
        return Variation(key, dist, values=tuple(arg))
    if not isinstance(arg, list) or len(arg) != 2 or not all(_is_number(v) for v in arg):
        what = "[mean, sd]" if dist == "normal" else "[low, high]"
        raise CampaignError(f"{where}: {dist} must be {what}, two numbers, not {arg!r}")
    a, b = float(arg[0]), float(arg[1])
    if dist == "normal":
        low, high = raw.get("min", -math.inf), raw.get("max", math.inf)
        if b < 0 or not (_is_number(low) or low == -math.inf) or \
                not (_is_number(high) or high == math.inf) or low > high:
            raise CampaignError(f"{where}: normal needs sd >= 0 and numbers min <= max")
        return Variation(key, dist, mean=a, sd=b, low=float(low), high=float(high))
    if a > b:
        raise CampaignError(f"{where}: {dist} = [{a:g}, {b:g}] needs low <= high")
    if dist == "integers" and not (a.is_integer() and b.is_integer()):
        raise CampaignError(f"{where}: integers = [low, high] must be whole numbers")
    return Variation(key, dist, low=a, high=b)


@dataclass(frozen=True)
class BaseScenario:
    """A scenario a campaign varies: as named, its file, its kind and its parsed TOML."""

    ref: str
    path: Path
    kind: str  #: one of KINDS
    data: Mapping[str, Any]

    @property
    def name(self) -> str:
        head = self.data.get("scenario", {})
        name = head.get("name") if isinstance(head, Mapping) else None
        return str(name) if name else self.path.stem


def kind_of(data: Mapping[str, Any]) -> str:
    from lowerbase.scenarios.wheeled import robot_of

    if "tasks" in data:
        return "tasks"
    if "trace" in data:
        return "trace"
    return "legged" if robot_of(data) == "legged" else "wheeled"


def find_base(ref: str, here: Path) -> BaseScenario:
    """A scenario by path (relative to the campaign file's folder), library name, or
    ``trace/NAME``."""
    from lowerbase.scenarios.catalog import find_scenario
    from lowerbase.scenarios.trace import library_trace

    p = here / ref
    if p.is_file():
        path = p
    elif ref.startswith("trace/") and ref[6:] in library_trace():
        path = library_trace()[ref[6:]]
    else:
        try:
            path = find_scenario(ref)
        except ConfigError as e:
            raise CampaignError(f"[campaign] scenario: {e}") from None
    data = read_toml(path, "scenario")
    return BaseScenario(ref, path.resolve(), kind_of(data), data)


@dataclass(frozen=True)
class Campaign:
    name: str
    source: Path  #: the campaign file
    scenarios: tuple[BaseScenario, ...]
    variations: tuple[Variation, ...]
    runs: int  #: samples per base scenario (per grid point with ``grid``)
    grid: bool  #: cross every list of values instead of sampling them
    seed: int
    reseed: bool  #: every run gets its own simulation seeds (profile imu.seed, truth.seed)
    timeline: tuple[Mapping[str, Any], ...] = ()  #: appended to each scenario's timeline
    expect: tuple[Mapping[str, Any], ...] = ()  #: appended to each scenario's expectations
    keep_expect: bool = True  #: False: only the campaign's expectations are scored
    description: str = ""
    metric: str = ""  #: [report] the metric plotted over each varied value
    threshold: float | None = None  #: [report] drawn as a line on those plots

    @property
    def axes(self) -> tuple[Variation, ...]:
        return tuple(v for v in self.variations if v.is_axis(self.grid))

    @property
    def grid_size(self) -> int:
        return math.prod(len(v.values) for v in self.axes)

    @property
    def per_scenario(self) -> int:
        return self.grid_size * self.runs

    @property
    def total(self) -> int:
        return len(self.scenarios) * self.per_scenario


def _tables(data: Mapping[str, Any], key: str) -> tuple[Mapping[str, Any], ...]:
    items = data.get(key, [])
    if not isinstance(items, list) or not all(isinstance(i, Mapping) for i in items):
        raise CampaignError(f"{key} must be an array of tables ([[{key}]])")
    return tuple(items)


def campaign_from_dict(data: Mapping[str, Any], path: Path) -> Campaign:
    _unknown("the file", data, _TOP)
    head = data.get("campaign")
    if not isinstance(head, Mapping):
        raise CampaignError("missing [campaign] table (name, scenario, runs, seed)")
    _unknown("[campaign]", head, _CAMPAIGN_KEYS)
    refs: Any = head.get("scenarios", head.get("scenario"))
    if "scenario" in head and "scenarios" in head:
        raise CampaignError("[campaign]: give scenario or scenarios, not both")
    if isinstance(refs, str):
        refs = [refs]
    if not isinstance(refs, list) or not refs or not all(isinstance(r, str) for r in refs):
        raise CampaignError("[campaign]: scenario = \"NAME|FILE\" (or scenarios = [...]) "
                            "is required")
    grid = head.get("grid", False)
    reseed = head.get("reseed", True)
    keep = head.get("keep_expect", True)
    for key, flag in (("grid", grid), ("reseed", reseed), ("keep_expect", keep)):
        if not isinstance(flag, bool):
            raise CampaignError(f"[campaign]: {key} must be true or false, not {flag!r}")
    runs = head.get("runs", 1 if grid else None)
    if isinstance(runs, bool) or not isinstance(runs, int) or not 1 <= runs <= MAX_RUNS:
        raise CampaignError(f"[campaign]: runs must be an integer 1..{MAX_RUNS} (runs per "
                            f"scenario, per grid point with grid = true), not {runs!r}")
    seed = head.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise CampaignError(f"[campaign]: seed must be an integer >= 0, not {seed!r}")
    vary = data.get("vary", {})
    if not isinstance(vary, Mapping):
        raise CampaignError("[vary] must be a table of KEY = distribution")
    variations = tuple(parse_variation(str(k), v) for k, v in vary.items())
    report = data.get("report", {})
    if not isinstance(report, Mapping):
        raise CampaignError("[report] must be a table (metric, threshold)")
    _unknown("[report]", report, _REPORT_KEYS)
    threshold = report.get("threshold")
    if threshold is not None and not _is_number(threshold):
        raise CampaignError(f"[report]: threshold must be a number, not {threshold!r}")
    metric = report.get("metric", "")
    if not isinstance(metric, str):
        raise CampaignError(f"[report]: metric must be a metric's column name, not {metric!r}")
    here = path.parent
    name = head.get("name", path.stem)
    campaign = Campaign(
        name=str(name), source=path.resolve(),
        scenarios=tuple(find_base(r, here) for r in refs), variations=variations,
        runs=runs, grid=grid, seed=seed, reseed=reseed,
        timeline=_tables(data, "timeline"), expect=_tables(data, "expect"), keep_expect=keep,
        description=str(head.get("description", "")), metric=metric,
        threshold=None if threshold is None else float(threshold))
    if metric:
        known = tuple(dict.fromkeys(m for b in campaign.scenarios for m in METRICS[b.kind]))
        known = (*known, WALL_METRIC)
        if metric not in known:
            close = difflib.get_close_matches(metric, known, n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"known: {', '.join(known)}"
            raise CampaignError(f"[report]: metric {metric!r} is not a column of these runs; "
                                f"{hint}")
    if campaign.total > MAX_RUNS:
        raise CampaignError(f"{campaign.total} runs: more than {MAX_RUNS}; lower runs or "
                            "the grid")
    if not keep and not campaign.expect:
        raise CampaignError("[campaign] keep_expect = false needs [[expect]] tables to score")
    return campaign
