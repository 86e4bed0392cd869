"""The ``[world]`` table of a scenario and its expectations (``localization``, ``contact``).

::

    [world]
    map = "warehouse"              # a shipped map name or a map .yaml (relative to the file)
    start = "start"                # a place of the map, or [x, y, yaw] [m, rad]
    localization = "filter"        # filter (amcl), truth, off
    initial_error = [0.1, 0.0, 0.05]  # the localizer's initial pose error (robot frame)
    [[world.obstacles]]            # obstacles_from_dicts: kind = "box" | "person", ...

A scenario with a world runs in-process only (the world reads the emulator's truth). The trace
gets ``amcl_x/y/yaw`` (movebase_pose2d, map frame), ``amcl_error`` [m], ``amcl_yaw_error``
[rad] against the truth, and ``contact``: a bit mask of what the footprint touches, bit i for
``WorldSpec.contact_names[i]`` ("wall", "map_edge", then the obstacles in order).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from lowerbase.errors import ConfigError, LowerbaseError
from lowerbase.scenarios.expect import Expectation, Outcome, Trace

if TYPE_CHECKING:
    from lowerbase.world.sim import WorldConfig, WorldSim

WORLD_KEYS = {"map", "start", "localization", "initial_error", "obstacles", "camera", "seed"}


@dataclass(frozen=True)
class WorldSpec:
    map: str = "warehouse"
    start: tuple[float, float, float] | str = "start"
    localization: str = "filter"
    initial_error: tuple[float, float, float] = (0.0, 0.0, 0.0)
    obstacles: tuple[Mapping[str, Any], ...] = ()
    camera: bool = False
    seed: int = 0
    contact_names: tuple[str, ...] = field(default=("wall", "map_edge"))

    def config(self) -> WorldConfig:
        from lowerbase.world.obstacles import obstacles_from_dicts
        from lowerbase.world.sim import WorldConfig

        return WorldConfig(map=self.map, start=self.start, localization=self.localization,
                           initial_error=self.initial_error,
                           obstacles=obstacles_from_dicts(self.obstacles), camera=self.camera,
                           seed=self.seed)


def _triple(value: Any, key: str) -> tuple[float, float, float]:
    if (not isinstance(value, list) or len(value) != 3 or any(
            isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v)
            for v in value)):
        raise ConfigError(f"[world]: {key} must be [x, y, yaw] finite numbers, not {value!r}")
    return float(value[0]), float(value[1]), float(value[2])


def parse_world(data: Any, base: Path | None) -> WorldSpec:
    """The ``[world]`` table, checked by building the world once (map, start, obstacles):
    a bad map, a start in a wall or a bad obstacle is one ConfigError line at load time."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"[world] must be a table, not {data!r}")
    unknown = sorted(set(data) - WORLD_KEYS)
    if unknown:
        raise ConfigError(f"[world]: unknown key {unknown[0]!r}; known: "
                          f"{', '.join(sorted(WORLD_KEYS))}")
    map_ref = data.get("map", "warehouse")
    if not isinstance(map_ref, str):
        raise ConfigError(f"[world]: map must be a map name or a .yaml path, not {map_ref!r}")
    if map_ref.endswith((".yaml", ".yml")) and base is not None and \
            not Path(map_ref).is_absolute():
        map_ref = str(base / map_ref)
    start = data.get("start", "start")
    start_value = start if isinstance(start, str) else _triple(start, "start")
    obstacles = data.get("obstacles", [])
    if not isinstance(obstacles, list) or not all(isinstance(o, Mapping) for o in obstacles):
        raise ConfigError("[world]: obstacles must be an array of tables ([[world.obstacles]])")
    camera, seed = data.get("camera", False), data.get("seed", 0)
    if not isinstance(camera, bool):
        raise ConfigError(f"[world]: camera must be true or false, not {camera!r}")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ConfigError(f"[world]: seed must be an integer, not {seed!r}")
    spec = WorldSpec(map=map_ref, start=start_value,
                     localization=str(data.get("localization", "filter")),
                     initial_error=_triple(data.get("initial_error", [0.0, 0.0, 0.0]),
                                           "initial_error"),
                     obstacles=tuple(obstacles), camera=camera, seed=seed,
                     contact_names=("wall", "map_edge",
                                    *(str(o.get("name", "?")) for o in obstacles)))
    try:
        from lowerbase.world.footprint import validate_pose
        from lowerbase.world.maps import load_map
        from lowerbase.world.sim import LOCALIZATION_MODES, resolve_start

        if spec.localization not in LOCALIZATION_MODES:
            raise ConfigError(f"[world]: localization = {spec.localization!r} is not known; "
                              f"one of: {', '.join(LOCALIZATION_MODES)}")
        cfg = spec.config()
        grid = load_map(spec.map)
        validate_pose(resolve_start(spec.map, grid, spec.start), grid, cfg.obstacles,
                      what="the robot's start pose")
    except ConfigError:
        raise
    except LowerbaseError as e:
        raise ConfigError(f"[world]: {e}") from None
    return spec


def world_sample(world: WorldSim, names: tuple[str, ...]) -> dict[str, float]:
    """The world's trace columns now."""
    s: dict[str, float] = {}
    est = world.amcl_pose()
    if est is not None:
        s.update(amcl_x=est[0], amcl_y=est[1], amcl_yaw=est[2])
        err = world.localization_error()
        if err is not None:
            s.update(amcl_error=err[0], amcl_yaw_error=err[1])
    hit = world.contact
    s["contact"] = float(sum(1 << names.index(n) for n in hit.touched if n in names)) \
        if hit is not None else 0.0
    return s


# -- expectations ------------------------------------------------------------------------------

def make_expectation(kind: str, t: Any, name: str, duration: float,
                     world: WorldSpec | None) -> Any:
    """``localization`` or ``contact`` from an [[expect]] table ``t`` (scenario._Table)."""
    if world is None:
        raise ConfigError(f"{t.where}: needs a [world] table")
    during = t.interval("during") or (0.0, duration)
    if kind == "localization":
        stat = t.text("stat", "p95", choices=("p95", "max"))
        within = t.number("within", math.inf, lo=0.0)
        yaw_within = t.number("yaw_within", math.inf, lo=0.0)
        if not (t.has("within") or t.has("yaw_within")):
            raise ConfigError(f"{t.where}: give within [m] and/or yaw_within [rad]")
        return LocalizationWithin(name, during=during, stat=stat, within=within,
                                  yaw_within=yaw_within)
    touched = t.text("with", "") or None
    if touched is not None and touched not in world.contact_names:
        raise ConfigError(f"{t.where}: with = {touched!r} is not known; one of: "
                          f"{', '.join(world.contact_names)}")
    bit = 0 if touched is None else 1 << world.contact_names.index(touched)
    return ContactHappened(name, during=during, happened=t.flag("happened", True),
                           touched=touched or "", bit=bit)


@dataclass(frozen=True)
class LocalizationWithin(Expectation):
    """The localization error's p95 (or max) during a window within bounds."""

    during: tuple[float, float] = (0.0, math.inf)
    stat: str = "p95"
    within: float = math.inf  #: [m]
    yaw_within: float = math.inf  #: [rad]
    kind: ClassVar[str] = "localization"

    def describe(self) -> str:
        bounds = [f"{self.within:g} m" if math.isfinite(self.within) else "",
                  f"{self.yaw_within:g} rad" if math.isfinite(self.yaw_within) else ""]
        return (f"localization error {self.stat} within {' and '.join(b for b in bounds if b)}"
                f" during [{self.during[0]:g}, {self.during[1]:g}] s")

    def evaluate(self, trace: Trace) -> Outcome:
        mask = trace.window(*self.during)
        pos, yaw = trace["amcl_error"][mask], trace["amcl_yaw_error"][mask]
        known = np.isfinite(pos)
        if not known.any():
            return Outcome("failed", "no localization estimate in the window")
        pick = (lambda a: float(np.max(a))) if self.stat == "max" else \
            (lambda a: float(np.percentile(a, 95)))
        p, h = pick(pos[known]), pick(yaw[known])
        ok = p <= self.within and h <= self.yaw_within and bool(known.all())
        missing = "" if known.all() else f", {int((~known).sum())} samples without an estimate"
        return Outcome("passed" if ok else "failed",
                       f"{self.stat} {p:.3f} m, {math.degrees(h):.2f} deg{missing}")


@dataclass(frozen=True)
class ContactHappened(Expectation):
    """Contact (with anything, or with ``touched``) happened / never happened in a window."""

    during: tuple[float, float] = (0.0, math.inf)
    happened: bool = True
    touched: str = ""
    bit: int = 0
    kind: ClassVar[str] = "contact"

    def describe(self) -> str:
        what = f" with {self.touched}" if self.touched else ""
        return (f"contact{what} {'happens' if self.happened else 'never happens'} during "
                f"[{self.during[0]:g}, {self.during[1]:g}] s")

    def evaluate(self, trace: Trace) -> Outcome:
        mask = trace.window(*self.during)
        bits = np.nan_to_num(trace["contact"][mask]).astype(np.int64)
        hits = (bits & self.bit) != 0 if self.bit else bits != 0
        times = trace["t"][mask][hits]
        seen = bool(hits.any())
        detail = f"first at t={times[0]:.2f} s" if seen else "no contact"
        return Outcome("passed" if seen == self.happened else "failed", detail)
