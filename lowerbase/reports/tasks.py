"""The report of a task scenario run (lowerbase/scenarios/tasks.py) and its CLI glue.

Files written to the report directory:

* ``map.png``: the map with the obstacles, the storage marks, the charger, every path the
  navigator planned, the driven path (ground truth) and the localization estimate;
* ``timeline.png``: robot_status task_state, action_type and robot_state over time (steps);
* ``battery.png``: the SOC (the BMS's, and the pack model's exact one) and the pack current
  (+ charging), with the charger contact;
* ``summary.json``: verdict, expectations, the robot_status timeline as published, the final
  poses, the planned paths, the driven distance, the battery;
* ``junit.xml``: one testcase per expectation; ``trace.csv``: the samples; ``run.log``;
* ``index.html``: all of the above on one page, the timeline as a table.
"""

from __future__ import annotations

import argparse
import csv
import html
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from lowerbase.errors import ConfigError
from lowerbase.reports.wheeled import _pyplot, junit_xml
from lowerbase.scenarios.expect import Outcome
from lowerbase.scenarios.tasks import FIELDS, TasksScenario
from lowerbase.scenarios.tasks_run import SAMPLE_COLUMNS, TasksResult, run_tasks_scenario
from lowerbase.tasks.model import TaskType

PLOTS = ("map.png", "timeline.png", "battery.png")
FILES = (*PLOTS, "summary.json", "junit.xml", "trace.csv", "index.html")


def _name(field: str, value: int) -> str:
    try:
        return FIELDS[field](value).name.lower()
    except ValueError:
        return str(value)


def columns(result: TasksResult) -> dict[str, np.ndarray]:
    """The samples column by column (SAMPLE_COLUMNS)."""
    data = np.array(result.samples, dtype=float).reshape(-1, len(SAMPLE_COLUMNS))
    return {name: data[:, i] for i, name in enumerate(SAMPLE_COLUMNS)}


def timeline(result: TasksResult) -> list[dict[str, Any]]:
    """robot_status as published (on change), one entry per message."""
    out = []
    for t, s in result.history:
        row: dict[str, Any] = {"t": round(t, 3), "task_id": s.task_id,
                               "task_type": _type_name(s.task_type)}
        row.update({f: _name(f, int(getattr(s, f))) for f in FIELDS})
        row["msg"] = s.msg
        out.append(row)
    return out


def _type_name(code: int) -> str:
    try:
        return TaskType(code).name.lower()
    except ValueError:
        return str(code)


def _finite(x: float) -> float | None:
    return round(float(x), 4) if math.isfinite(x) else None


def _pose(c: dict[str, np.ndarray], prefix: str) -> dict[str, float | None] | None:
    if not len(c["t"]):
        return None
    return {k: _finite(c[f"{prefix}_{k}"][-1]) for k in ("x", "y", "yaw")}


def summarize(result: TasksResult) -> dict[str, Any]:
    s, c = result.scenario, columns(result)
    passed = sum(1 for _, ok, _ in result.outcomes if ok)
    x, y = c["truth_x"], c["truth_y"]
    final: dict[str, Any] = {"truth": _pose(c, "truth"), "estimate": _pose(c, "est")}
    if len(x) and math.isfinite(c["est_x"][-1]):
        final["estimate_error_m"] = _finite(math.hypot(c["est_x"][-1] - x[-1],
                                                       c["est_y"][-1] - y[-1]))
    charging = c["current"] > 0
    battery = {"soc_start": _finite(c["pack_soc"][0]) if len(x) else None,
               "soc_min": _finite(np.nanmin(c["pack_soc"])) if len(x) else None,
               "soc_end": _finite(c["pack_soc"][-1]) if len(x) else None,
               "max_charge_current_a": _finite(float(np.nanmax(c["current"]))) if len(x) else None,
               "charging_s": round(float(charging.sum()) * _period(c), 3),
               "charger_contact_s": round(float((c["charger"] > 0).sum()) * _period(c), 3)}
    return {
        "scenario": s.name, "description": s.description, "source": s.source,
        "kind": "tasks", "mode": "simulated", "passed": result.passed,
        "interrupted": result.interrupted, "duration_s": s.duration,
        "simulated_s": round(float(c["t"][-1]), 3) if len(x) else 0.0,
        "wall_time_s": round(result.wall_time, 3),
        "counts": {"passed": passed, "failed": len(result.outcomes) - passed, "skipped": 0},
        "expectations": [{"name": e.title(), "kind": e.kind,
                          "status": "passed" if ok else "failed", "detail": why}
                         for e, ok, why in result.outcomes],
        "requests": [{"t": round(t, 3), "task_id": i, "success": ok, "message": m}
                     for t, i, ok, m in result.responses],
        "timeline": timeline(result),
        "final": final,
        "driven_m": round(float(np.hypot(np.diff(x), np.diff(y)).sum()), 4),
        "plans": [{"t": round(t, 3), "start": list(p[0]), "end": list(p[-1]),
                   "length_m": round(_length(p), 4)} for t, p in result.plans],
        "battery": battery,
        "files": list(FILES),
    }


def _period(c: dict[str, np.ndarray]) -> float:
    t = c["t"]
    return float(np.median(np.diff(t))) if len(t) > 1 else 0.0


def _length(path: list[tuple[float, float, float]]) -> float:
    a = np.asarray(path)[:, :2]
    return float(np.hypot(*np.diff(a, axis=0).T).sum()) if len(a) > 1 else 0.0


def write_tasks_report(result: TasksResult, out: Path) -> dict[str, Any]:
    """Write every report file into ``out`` (created); returns the summary."""
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize(result)
    if (out / "run.log").exists():  # the run's log records (run_and_report)
        summary["files"].append("run.log")
    c = columns(result)
    with (out / "trace.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(SAMPLE_COLUMNS)
        for row in zip(*(c[k] for k in SAMPLE_COLUMNS), strict=True):
            w.writerow(["" if not math.isfinite(v) else f"{v:.6g}" for v in row])
    plot_map(result, out / "map.png")
    plot_timeline(result, out / "timeline.png")
    plot_battery(result, out / "battery.png")
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    s = result.scenario
    junit_xml(s.name, (("source", s.source), ("mode", "simulated"), ("kind", "tasks"),
                       ("simulated_s", f"{summary['simulated_s']:g}")),
              outcomes(result), result.interrupted, result.wall_time, out / "junit.xml")
    write_index(result, summary, out / "index.html")
    return summary


def outcomes(result: TasksResult) -> list[tuple[Any, Outcome]]:
    return [(e, Outcome("passed" if ok else "failed", why)) for e, ok, why in result.outcomes]


def write_index(result: TasksResult, summary: dict[str, Any], path: Path) -> None:
    s = result.scenario
    verdict = "INTERRUPTED" if result.interrupted else "PASSED" if result.passed else "FAILED"
    rows = "\n".join(
        f"<tr class='{e['status']}'><td>{e['status'].upper()}</td><td>{html.escape(e['name'])}"
        f"</td><td>{html.escape(e['detail'])}</td></tr>" for e in summary["expectations"])
    keys = ("t", "task_id", "task_type", "task_state", "action_type", "action_state",
            "robot_state", "msg")
    status = "\n".join("<tr>" + "".join(f"<td>{html.escape(str(r[k]))}</td>" for k in keys)
                       + "</tr>" for r in summary["timeline"])
    images = "\n".join(f"<p><img src='{p}' alt='{p}'></p>" for p in PLOTS)
    b = summary["battery"]
    path.write_text(f"""<!doctype html>
<html><head><meta charset="utf-8"><title>{html.escape(s.name)}: {verdict}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}
td,th{{padding:2px 8px;text-align:left}} .passed td:first-child{{color:green}}
.failed td:first-child{{color:#c00;font-weight:bold}} img{{max-width:100%}}</style>
</head><body>
<h1>{html.escape(s.name)}: {verdict}</h1>
<p>{html.escape(s.description)}</p>
<p>{summary['simulated_s']:.1f} s on the simulated clock in {result.wall_time:.1f} s of wall
time; driven {summary['driven_m']:.1f} m, {len(summary['plans'])} plan(s); SOC
{b['soc_start']} -> {b['soc_min']} (min) -> {b['soc_end']} %; source
<code>{html.escape(s.source)}</code>; also <a href="summary.json">summary.json</a>,
<a href="junit.xml">junit.xml</a>, <a href="trace.csv">trace.csv</a>.</p>
<table>{rows}</table>
{images}
<h2>robot_status (as published)</h2>
<table><tr>{''.join(f'<th>{k}</th>' for k in keys)}</tr>
{status}</table>
</body></html>
""", encoding="utf-8")


# -- plots -------------------------------------------------------------------------------------


def plot_map(result: TasksResult, path: Path) -> None:
    from matplotlib.patches import Circle, Polygon

    plt = _pyplot()
    ts, c = result.sim, columns(result)
    grid = ts.world.grid
    fig, ax = plt.subplots(figsize=(11, 7.5))
    x0, y0 = grid.origin[0], grid.origin[1]
    occupied = grid.occupied()
    h, w = occupied.shape
    ax.imshow(np.where(occupied, 0.2, 1.0), cmap="gray", vmin=0, vmax=1, origin="lower",
              extent=(x0, x0 + w * grid.resolution, y0, y0 + h * grid.resolution))
    for prism in ts.world.obstacles.prisms_at(0.0):
        if prism.polygon is not None:
            poly = np.asarray(prism.polygon)[:, :2]
            ax.add_patch(Polygon(poly, color="tab:orange", alpha=0.8))
            ax.annotate(prism.name, tuple(poly.mean(axis=0)), fontsize=8, ha="center")
        elif prism.circle is not None:
            cx, cy, r = prism.circle
            ax.add_patch(Circle((cx, cy), r, color="tab:orange", alpha=0.8))
    for name, (px, py, _) in ts.places.storage.items():
        ax.plot(px, py, "s", color="tab:green", ms=4)
        ax.annotate(name, (px, py), fontsize=6, xytext=(3, 3), textcoords="offset points")
    if ts.places.charger is not None:
        cx, cy, _ = ts.places.charger.pose
        ax.plot(cx, cy, "P", color="tab:red", ms=10, label="charger")
    for i, (_, plan) in enumerate(result.plans):
        p = np.asarray(plan)
        ax.plot(p[:, 0], p[:, 1], "--", color="tab:blue", lw=1, alpha=0.6,
                label="planned paths" if i == 0 else None)
    ax.plot(c["truth_x"], c["truth_y"], color="black", lw=2, label="driven (ground truth)")
    ax.plot(c["est_x"], c["est_y"], color="tab:purple", lw=1, label="localization estimate")
    if len(c["t"]):
        ax.plot(c["truth_x"][0], c["truth_y"][0], "o", color="black", label="start")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(f"{result.scenario.name}: map, marks, charger, paths")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _steps(result: TasksResult, field: str) -> tuple[list[float], list[int]]:
    end = result.samples[-1][0] if result.samples else 0.0
    t = [h[0] for h in result.history] + [end]
    v = [int(getattr(h[1], field)) for h in result.history]
    return t, v + v[-1:]


def plot_timeline(result: TasksResult, path: Path) -> None:
    plt = _pyplot()
    fields = ("task_state", "action_type", "robot_state")
    fig, axes = plt.subplots(len(fields), 1, figsize=(11, 7), sharex=True)
    for ax, field in zip(axes, fields, strict=True):
        t, v = _steps(result, field)
        ax.step(t, v, where="post", color="black")
        enum = FIELDS[field]
        ax.set_yticks([int(m) for m in enum], [m.name.lower() for m in enum], fontsize=7)
        ax.set_ylabel(field)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    axes[0].set_title(f"{result.scenario.name}: robot_status")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_battery(result: TasksResult, path: Path) -> None:
    plt = _pyplot()
    c = columns(result)
    fig, (a, b) = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    a.plot(c["t"], c["soc"], color="tab:green", lw=1.5, label="BMS (driver)")
    a.plot(c["t"], c["pack_soc"], color="black", ls="--", lw=1, label="pack model (exact)")
    a.set_ylabel("SOC [%]")
    a.legend(fontsize=8)
    b.plot(c["t"], c["current"], color="tab:purple", lw=1, label="pack current (+ charging)")
    b.fill_between(c["t"], 0, c["charger"] * max(float(np.nanmax(c["current"], initial=0)), 1),
                   color="tab:red", alpha=0.15, step="post", label="charger contact")
    b.set_ylabel("current [A]")
    b.set_xlabel("t [s]")
    b.legend(fontsize=8)
    a.set_title(f"{result.scenario.name}: battery")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# -- the commands ------------------------------------------------------------------------------


def run_and_report(scenario: TasksScenario, out: Path, progress: Any = None, *,
                   debug: bool = False, mcap: str | Path | None = None,
                   foxglove: str | None = None) -> tuple[TasksResult, dict[str, Any] | None]:
    """Run ``scenario`` (log records to ``out/run.log``) and write its report; the summary is
    None when Ctrl-C came before the robot was built (nothing to report). ``mcap``: record
    the run there; ``foxglove``: HOST:PORT of a live view (docs/recording.md)."""
    from lowerbase.recording.mcap_writer import open_publisher
    from lowerbase.reports.outputs import log_to_file

    publisher = None
    try:
        publisher = open_publisher(mcap, foxglove,
                                   announce=lambda line: print(line, file=sys.stderr))
        with log_to_file(out / "run.log", echo=debug):
            result = run_tasks_scenario(scenario, progress=progress, publisher=publisher)
    finally:
        if publisher is not None:
            publisher.close()
        if progress is not None:
            progress.done()
    if result.sim is None:
        return result, None
    return result, write_tasks_report(result, out)


def print_outcomes(result: TasksResult, stream: Any = None) -> None:
    stream = stream or sys.stdout
    for e, ok, why in result.outcomes:
        print(f"  {'PASSED' if ok else 'FAILED':<7} {e.title()}: {why}", file=stream)
    failed = sum(1 for _, ok, _ in result.outcomes if not ok)
    verdict = "INTERRUPTED" if result.interrupted else "PASSED" if result.passed else "FAILED"
    end = result.samples[-1][0] if result.samples else 0.0
    print(f"scenario {result.scenario.name}: {verdict} ({len(result.outcomes) - failed} "
          f"passed, {failed} failed); {end:.1f} s simulated in {result.wall_time:.1f} s",
          file=stream)


def exit_code(result: TasksResult) -> int:
    return 130 if result.interrupted else 0 if result.passed else 1


def run_command(args: argparse.Namespace, scenario: TasksScenario, out: Path) -> int:
    """``lowerbase scenario run`` for a task scenario (in this process, simulated clock)."""
    from lowerbase.reports.outputs import mcap_path
    from lowerbase.scenarios.demo import ProgressBar, TaskStatusLine

    refused = [flag for flag, given in (
        ("--realtime", args.mode == "realtime"), ("--processes", args.mode == "processes"),
        ("--record", args.record)) if given]
    if refused:
        raise ConfigError(f"a task scenario runs in this process on the simulated clock; "
                          f"drop {refused[0]}")
    mcap = mcap_path(out, True if args.mcap is None else args.mcap)
    progress: Any = TaskStatusLine(force=True, period=10.0) if args.status else \
        ProgressBar(scenario.duration, force=args.progress)
    print(f"scenario {scenario.name}: {scenario.description or scenario.source} "
          f"({scenario.duration:g} s, tasks, simulated)", file=sys.stderr)
    result, summary = run_and_report(scenario, out, progress, debug=args.debug, mcap=mcap,
                                     foxglove=args.foxglove)
    if summary is None:
        return 130
    print_outcomes(result)
    print(f"report: {out / 'index.html'} (map.png, timeline.png, battery.png, summary.json, "
          f"junit.xml)")
    if mcap is not None:
        print(f"mcap: {mcap} (Foxglove, PlotJuggler; `lowerbase mcap to-bag` for rosbag)")
    return exit_code(result)
