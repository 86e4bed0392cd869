"""The report of a legged scenario run and its ``lowerbase scenario run`` glue.

The wheeled report's files (docs/scenarios.md) for the legged robot: ``summary.json``,
``junit.xml`` (one testcase per expectation), ``trace.csv`` (every trace column),
``legged.png`` (path, locomotion state, actuator temperatures) and ``index.html``.
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

from lowerbase.errors import ConfigError
from lowerbase.reports.wheeled import junit_xml
from lowerbase.scenarios.legged import STATES, LeggedScenario
from lowerbase.scenarios.legged_run import LeggedRunResult, run_legged_scenario


def write_legged_report(result: LeggedRunResult, out: Path) -> dict[str, Any]:
    """Write the report files into ``out`` (created); returns the summary."""
    out.mkdir(parents=True, exist_ok=True)
    s, trace = result.scenario, result.trace
    counts = {k: sum(1 for _, o in result.outcomes if o.status == k)
              for k in ("passed", "failed", "skipped")}
    last = trace.rows[-1] if trace.rows else {}
    state = int(last.get("state", -1))
    summary: dict[str, Any] = {
        "scenario": s.name, "robot": s.robot, "description": s.description,
        "source": s.source, "mode": result.mode, "passed": result.passed,
        "interrupted": result.interrupted, "duration_s": s.duration,
        "simulated_s": trace.end, "wall_time_s": round(result.wall_time, 3),
        "initial": {"soc": s.soc}, "counts": counts,
        "expectations": [{"name": e.title(), "kind": e.kind, "status": o.status,
                          "detail": o.detail} for e, o in result.outcomes],
        "events": [{"t": round(t, 4), "what": w} for t, w in result.events],
        "answers": [vars(a) for a in result.answers],
        "final": {"base_pos": [last.get(k) for k in ("x", "y", "z")],
                  "state": next((k for k, v in STATES.items() if v == state), None),
                  "fault": int(last.get("fault", 0))},
        "files": ["legged.png", "summary.json", "junit.xml", "trace.csv", "index.html"],
    }
    with (out / "trace.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(trace.columns)
        for row in trace.rows:
            w.writerow(["" if not math.isfinite(v) else f"{v:.6g}" for v in row.values()])
    _plot(result, out / "legged.png")
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    _junit(result, out / "junit.xml")
    rows = "\n".join(f"<tr><td>{e['status'].upper()}</td><td>{html.escape(e['name'])}</td>"
                     f"<td>{html.escape(e['detail'])}</td></tr>" for e in summary["expectations"])
    verdict = "PASSED" if result.passed else "FAILED"
    (out / "index.html").write_text(
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(s.name)}: "
        f"{verdict}</title></head><body><h1>{html.escape(s.name)}: {verdict}</h1>"
        f"<p>{html.escape(s.description)}</p><p>{result.mode} run of {trace.end:.1f} s; "
        "<a href='summary.json'>summary.json</a>, <a href='junit.xml'>junit.xml</a>, "
        f"<a href='trace.csv'>trace.csv</a></p><table>{rows}</table>"
        "<p><img src='legged.png' alt='legged.png'></p></body></html>\n", encoding="utf-8")
    return summary


def _junit(result: LeggedRunResult, path: Path) -> None:
    s = result.scenario
    junit_xml(s.name, (("source", s.source), ("mode", result.mode), ("robot", s.robot),
                       ("simulated_s", f"{result.trace.end:g}")),
              result.outcomes, result.interrupted, result.wall_time, path)


def _plot(result: LeggedRunResult, path: Path) -> None:
    from lowerbase.reports.wheeled import _pyplot

    plt = _pyplot()
    tr = result.trace
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4.5))
    a.plot(tr["truth_x"], tr["truth_y"], color="black", lw=2, label="model")
    a.plot(tr["x"], tr["y"], color="tab:blue", lw=1, label="robot_state base_pos")
    a.set_aspect("equal", adjustable="datalim")
    a.set_xlabel("x [m]")
    a.set_ylabel("y [m]")
    a.legend(fontsize=8)
    b.step(tr["t"], tr["state"], where="post", color="black")
    b.set_yticks(range(10), list(STATES), fontsize=7)
    b.set_xlabel("t [s]")
    b.set_title("locomotion state")
    for name in tr.columns:
        if name.startswith("temp_"):
            c.plot(tr["t"], tr[name], lw=1, label=name[5:])
    c.set_xlabel("t [s]")
    c.set_ylabel("winding [degC]")
    c.legend(fontsize=6, ncol=2)
    fig.suptitle(result.scenario.name)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def run_command(args: argparse.Namespace, scenario: LeggedScenario, out: Path) -> int:
    """``lowerbase scenario run`` for a legged scenario (simulated or --realtime)."""
    refused = [flag for flag, given in (
        ("--processes", args.mode == "processes"), ("--record", args.record),
        ("--mcap", args.mcap not in (None, False)), ("--foxglove", args.foxglove)) if given]
    if refused:
        raise ConfigError(f"a legged scenario runs in this process on the simulated clock "
                          f"(or --realtime); drop {refused[0]}")
    print(f"scenario {scenario.name}: {scenario.description or scenario.source} "
          f"({scenario.duration:g} s, legged, {args.mode})", file=sys.stderr)
    result = run_legged_scenario(scenario, realtime=args.mode == "realtime")
    write_legged_report(result, out)
    for exp, outcome in result.outcomes:
        print(f"  {outcome.status.upper():<7} {exp.title()}: {outcome.detail}")
    failed = sum(1 for _, o in result.outcomes if o.status == "failed")
    verdict = "INTERRUPTED" if result.interrupted else "PASSED" if result.passed else "FAILED"
    print(f"scenario {scenario.name}: {verdict} ({len(result.outcomes) - failed} passed, "
          f"{failed} failed); {result.trace.end:.1f} s {result.mode} in "
          f"{result.wall_time:.1f} s")
    print(f"report: {out / 'index.html'} (legged.png, summary.json, junit.xml)")
    if result.interrupted:
        return 130
    return 0 if result.passed else 1
