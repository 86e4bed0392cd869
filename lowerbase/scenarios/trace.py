"""Trace scenarios: the seed's diagram (shared/seeds/001) on the simulated clock.

A trace scenario runs a :class:`~lowerbase.trace.sim.TraceSim` (emulator, driver_base core,
world, TraceNavigate, ObstacleNavigate) with a business node that answers as the seed's
diagram says (BLOCKED -> ObstacleNavigate; its FINISHED -> back to TraceNavigate). The wheeled
scenario format (scenario.py) has no route nor status topics, so these files live apart, in
``scenarios/trace/``, and run with ``python -m lowerbase.scenarios.trace NAME|FILE``::

    [scenario]
    name = "trace_diagram"; duration = 200.0   # [s] simulated
    [world]                                    # as scenario_world.py: map, start, obstacles ...
    map = "warehouse"; start = [6.0, 1.2, 0.0]; localization = "truth"
    [trace]                                    # TraceParams (status_period, blocked_timeout, ...)
    blocked_timeout = 60.0
    route = [[6.0, 1.2], [11.0, 1.2], [16.0, 1.2]]   # points [m]; speed [mm/s] below
    speed = 500
    [[expect]]
    topic = "msg_trace_navigate_status"        # the statuses seen there (repeats collapsed)
    sequence = ["RUNNING", "BLOCKED", "RUNNING", "FINISHED"]   # contain these, in order
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError, LowerbaseError
from lowerbase.files import read_toml
from lowerbase.trace import messages as m
from lowerbase.trace.modules import AVOID_ROUTE, AVOID_STATUS, ROUTE, STATUS

NAMES = {v: int(k) for k, v in m.STATUS_NAMES.items()}
BY_CODE = {int(k): v for k, v in m.STATUS_NAMES.items()}
TOPICS = (STATUS, AVOID_STATUS)
MAX_DURATION = 3600.0


@dataclass
class TraceScenario:
    name: str
    duration: float
    world: Any  #: scenario_world.WorldSpec
    params: dict[str, float]
    route: m.GTraceList
    expects: list[tuple[str, tuple[str, ...]]]
    description: str = ""


@dataclass
class TraceResult:
    scenario: TraceScenario
    seen: dict[str, list[str]] = field(default_factory=dict)  #: statuses, repeats collapsed
    outcomes: list[tuple[str, bool, str]] = field(default_factory=list)
    sim_time: float = 0.0
    wall_time: float = 0.0

    @property
    def passed(self) -> bool:
        return bool(self.outcomes) and all(ok for _, ok, _ in self.outcomes)


def _route(points: Any, speed: Any, map_name: str) -> m.GTraceList:
    if (not isinstance(points, list) or len(points) < 2 or any(
            not isinstance(p, list) or len(p) != 2 for p in points)):
        raise ConfigError("[trace] route must be a list of at least two [x, y] points")
    lst = m.GTraceList(map=map_name.encode())
    for a, b in itertools.pairwise(points):
        seg = lst.lists.add(finished=0.0)
        seg.first.x, seg.first.y, seg.first.angle = float(a[0]), float(a[1]), 0.0
        seg.second.x, seg.second.y, seg.second.angle = float(b[0]), float(b[1]), 0.0
        if speed:
            seg.first.speed = int(speed)
    lst.lists[0].first.starter = 1
    try:  # NaN, zero-length segments: one line now rather than a refusal later
        m.check_route(lst)
    except m.TraceError as exc:
        raise ConfigError(f"[trace] route: {exc}") from None
    return lst


def load_trace_scenario(path: str | Path) -> TraceScenario:
    """A trace scenario file; every mistake is one ConfigError line."""
    path = Path(path)
    return trace_scenario_from_dict(read_toml(path, "scenario"), path, path.parent)


def trace_scenario_from_dict(data: Mapping[str, Any], path: str | Path,
                             base: Path) -> TraceScenario:
    """A trace scenario from parsed TOML (``path``: its name in messages and its default
    name; ``base``: where relative map paths start)."""
    from lowerbase.scenarios.world import parse_world
    from lowerbase.trace.base import TraceParams

    path = Path(path)
    unknown = sorted(set(data) - {"scenario", "world", "trace", "expect"})
    if unknown:
        raise ConfigError(f"{path}: unknown table {unknown[0]!r}")
    head = data.get("scenario", {})
    duration = float(head.get("duration", 300.0))
    if not 0.1 <= duration <= MAX_DURATION:
        raise ConfigError(f"[scenario] duration {duration}: expected 0.1 .. {MAX_DURATION} s")
    world = parse_world(data.get("world", {}), base)
    trace = dict(data.get("trace", {}))
    route, speed = trace.pop("route", None), trace.pop("speed", 0)
    known = set(TraceParams.__dataclass_fields__) - {"map_name"}
    bad = sorted(set(trace) - known)
    if bad:
        raise ConfigError(f"[trace]: unknown key {bad[0]!r}; known: route, speed, "
                          f"{', '.join(sorted(known))}")
    TraceParams(**trace)  # checked now
    expects = []
    for i, e in enumerate(data.get("expect", [])):
        seq = e.get("sequence", [])
        if e.get("topic") not in TOPICS or not seq or any(s not in NAMES for s in seq):
            raise ConfigError(f"expect[{i}]: needs topic ({' or '.join(TOPICS)}) and a "
                              f"sequence of {', '.join(NAMES)}")
        expects.append((str(e["topic"]), tuple(seq)))
    return TraceScenario(str(head.get("name", path.stem)), duration, world, trace,
                         _route(route, speed, world.map), expects,
                         str(head.get("description", "")))


def library_trace() -> dict[str, Path]:
    """The library's trace scenarios (scenarios/trace/*.toml) by name."""
    here = Path(__file__).resolve()
    for d in (here.parents[2] / "scenarios" / "trace", here.parent / "library" / "trace"):
        if d.is_dir():
            return {p.stem: p for p in sorted(d.glob("*.toml"))}
    return {}


def run_trace_scenario(sc: TraceScenario) -> TraceResult:
    """Run ``sc`` on the simulated clock (the business node of the seed's diagram)."""
    from lowerbase.trace.base import TraceParams
    from lowerbase.trace.sim import TraceSim

    started = time.monotonic()
    sim = TraceSim(sc.world.config(), TraceParams(map_name=sc.world.map, **sc.params))

    def business(topic: str, msg: m.GTraceList) -> None:
        if topic == STATUS and msg.status == m.BLOCKED:
            sim.publish(AVOID_ROUTE, msg)
        elif topic == AVOID_STATUS and msg.status == m.FINISHED:
            sim.publish(ROUTE, msg)

    sim.listeners.append(business)
    sim.publish(ROUTE, sc.route)
    sim.run_until(lambda: any(r.status == m.FINISHED for _, r in sim.published[STATUS]),
                  sc.duration)
    result = TraceResult(sc, sim_time=sim.now, wall_time=time.monotonic() - started)
    for topic in TOPICS:
        names = [BY_CODE.get(s, str(s)) for _, s in sim.statuses(topic)]
        result.seen[topic] = [k for k, _ in itertools.groupby(names)]
    for topic, want in sc.expects:
        it = iter(result.seen[topic])
        ok = all(any(v == w for v in it) for w in want)
        result.outcomes.append((f"{topic} goes {' -> '.join(want)}", ok,
                                f"seen {' -> '.join(result.seen[topic]) or 'nothing'}"))
    return result


def report(result: TraceResult) -> str:
    lines = [f"{result.scenario.name}: {'PASSED' if result.passed else 'FAILED'} "
             f"({result.sim_time:.1f} s simulated in {result.wall_time:.1f} s)"]
    lines += [f"  {'ok ' if ok else 'BAD'} {what}: {why}" for what, ok, why in result.outcomes]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m lowerbase.scenarios.trace",
                                description="Run a trace scenario (the seed's diagram) on the "
                                "simulated clock.")
    p.add_argument("scenario", help=f"a file, or a library name ({', '.join(library_trace())})")
    args = p.parse_args(argv)
    try:
        path = library_trace().get(args.scenario, Path(args.scenario))
        if not path.is_file():
            raise ConfigError(f"no trace scenario {args.scenario!r}: give a file or one of "
                              f"{', '.join(library_trace()) or 'none'}")
        result = run_trace_scenario(load_trace_scenario(path))
    except LowerbaseError as exc:
        print(f"scenario_trace: error: {exc}", file=sys.stderr)
        return 2
    print(report(result))
    return 0 if result.passed else 1


if __name__ == "__main__":
    sys.exit(main())
