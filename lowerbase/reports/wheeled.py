"""The report of a scenario run: plots (PNG), a summary (JSON), JUnit XML and an index page.

Files written to the report directory:

* ``trajectory.png``: ground truth, /odom_raw (wheel odometry) and /odom (EKF) in the plane;
* ``velocities.png``: commanded, measured (MotionState) and true linear and angular velocity;
* ``battery.png``: SOC (BmsPack's integer percent, BmsCapacity remain/full, and the pack
  model's exact one when in process), pack voltage and current;
* ``status.png``: every StatusCode bit that was set, and the robot and link states, over time;
* ``summary.json``: pass/fail per expectation, final poses, events, file names;
* ``junit.xml``: one testcase per expectation (for CI);
* ``trace.csv``: the sampled trace, one row per sample;
* ``index.html``: all of the above on one page.

matplotlib is imported inside the plotting functions (Agg backend), so importing this module
costs nothing at CLI start.
"""

from __future__ import annotations

import csv
import html
import json
import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lowerbase.protocol.status_codes import StatusBit, describe
from lowerbase.scenarios.expect import COLUMNS, Trace
from lowerbase.scenarios.runner import RunResult
from lowerbase.scenarios.timeline import LINK_STATES, ROBOT_STATES

PLOTS = ("trajectory.png", "velocities.png", "battery.png", "status.png")


def write_report(result: RunResult, out: Path, *, recording: Path | None = None) -> dict[str, Any]:
    """Write every report file into ``out`` (created); returns the summary."""
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize(result, recording=recording)
    summary["files"] += [name for name in EXTRA_FILES if (out / name).exists()]
    write_trace_csv(result.trace, out / "trace.csv")
    plot_all(result, out)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    write_junit(result, out / "junit.xml")
    write_index(result, summary, out / "index.html")
    return summary


# -- machine-readable --------------------------------------------------------------------------


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _pose(trace: Trace, prefix: str) -> dict[str, float | None] | None:
    if not trace.has(f"{prefix}_x"):
        return None
    return {c: _finite(float(trace[f"{prefix}_{c}"][-1])) for c in ("x", "y", "yaw")}


def summarize(result: RunResult, *, recording: Path | None = None) -> dict[str, Any]:
    """The JSON summary of a run."""
    s, trace = result.scenario, result.trace
    final: dict[str, Any] = {
        "truth": _pose(trace, "truth"), "odom_raw": _pose(trace, "raw"),
        "odom": _pose(trace, "ekf"),
    }
    for name, prefix in (("odom_raw", "raw"), ("odom", "ekf")):
        if final["truth"] is not None and final[name] is not None:
            err = math.hypot(trace[f"{prefix}_x"][-1] - trace["truth_x"][-1],
                             trace[f"{prefix}_y"][-1] - trace["truth_y"][-1])
            final[f"{name}_error_m"] = _finite(err)
    if len(trace):
        final["soc"] = _finite(float(trace["soc"][-1]))
        final["status_code"] = int(trace["status"][-1])
        final["status"] = describe(int(trace["status"][-1]))
        state = int(trace["robot_state"][-1])
        final["robot_state"] = ROBOT_STATES[state] if 0 <= state < len(ROBOT_STATES) else None
    counts = {k: sum(1 for _, o in result.outcomes if o.status == k)
              for k in ("passed", "failed", "skipped")}
    return {
        "scenario": s.name,
        "description": s.description,
        "source": s.source,
        "mode": result.mode,
        "passed": result.passed,
        "interrupted": result.interrupted,
        "duration_s": s.duration,
        "simulated_s": trace.end,
        "wall_time_s": round(result.wall_time, 3),
        "host_lag": result.lag.as_dict() if result.lag is not None else None,
        "initial": {"soc": s.initial.soc, "x": s.initial.pose.x, "y": s.initial.pose.y,
                    "yaw": s.initial.pose.yaw, "charger": s.initial.charger},
        "counts": counts,
        "expectations": [
            {"name": exp.title(), "kind": exp.kind, "status": o.status, "detail": o.detail}
            for exp, o in result.outcomes
        ],
        "events": [{"t": round(t, 4), "what": what} for t, what in result.events],
        "final": final,
        "recording": str(recording) if recording else None,
        "files": [*PLOTS, "summary.json", "junit.xml", "trace.csv", "index.html"],
    }


EXTRA_FILES = ("run.log", "emulator.log", "truth.csv")


def write_junit(result: RunResult, path: Path) -> None:
    """One testsuite, one testcase per expectation; failures and skips with their detail."""
    s = result.scenario
    junit_xml(s.name, (("source", s.source), ("mode", result.mode),
                       ("simulated_s", f"{result.trace.end:g}")),
              result.outcomes, result.interrupted, result.wall_time, path)


def junit_xml(name: str, properties: Sequence[tuple[str, str]],
              outcomes: Sequence[tuple[Any, Any]], interrupted: bool, wall_time: float,
              path: Path) -> None:
    """The JUnit file of a scenario run (wheeled or legged): ``outcomes`` are (expectation,
    outcome) pairs with ``exp.title()``, ``exp.kind``, ``exp.describe()`` and
    ``outcome.status`` / ``outcome.detail``; an interrupted run adds one failed case."""
    failed = [o for _, o in outcomes if o.status == "failed"]
    skipped = [o for _, o in outcomes if o.status == "skipped"]
    suite = ET.Element("testsuite", {
        "name": f"scenario.{name}", "tests": str(len(outcomes) + interrupted),
        "failures": str(len(failed) + interrupted), "errors": "0",
        "skipped": str(len(skipped)), "time": f"{wall_time:.3f}",
    })
    props = ET.SubElement(suite, "properties")
    for key, value in properties:
        ET.SubElement(props, "property", {"name": key, "value": value})
    for exp, outcome in outcomes:
        case = ET.SubElement(suite, "testcase", {
            "classname": f"scenario.{name}", "name": exp.title(), "time": "0"})
        if outcome.status == "failed":
            node = ET.SubElement(case, "failure", {"message": outcome.detail,
                                                   "type": exp.kind})
            node.text = f"{exp.describe()}: {outcome.detail}"
        elif outcome.status == "skipped":
            ET.SubElement(case, "skipped", {"message": outcome.detail})
        else:
            ET.SubElement(case, "system-out").text = outcome.detail
    if interrupted:
        case = ET.SubElement(suite, "testcase", {"classname": f"scenario.{name}",
                                                 "name": "run completed", "time": "0"})
        ET.SubElement(case, "failure", {"message": "interrupted", "type": "interrupted"})
    root = ET.Element("testsuites")
    root.append(suite)
    tree = ET.ElementTree(root)
    ET.indent(tree)
    tree.write(path, encoding="utf-8", xml_declaration=True)


def write_trace_csv(trace: Trace, path: Path) -> None:
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow([f"{c} [{u}]" if u else c for c, u in COLUMNS.items()])
        cols = [trace[c] for c in COLUMNS]
        for row in zip(*cols, strict=True):
            w.writerow(["" if not math.isfinite(v) else f"{v:.6g}" for v in row])


def write_index(result: RunResult, summary: dict[str, Any], path: Path) -> None:
    s = result.scenario
    rows = "\n".join(
        f"<tr class='{e['status']}'><td>{e['status'].upper()}</td><td>{html.escape(e['name'])}"
        f"</td><td>{html.escape(e['detail'])}</td></tr>" for e in summary["expectations"])
    images = "\n".join(f"<p><img src='{p}' alt='{p}'></p>" for p in PLOTS)
    verdict = "PASSED" if result.passed else "FAILED"
    logs = "".join(f", <a href='{f}'>{f}</a>" for f in summary["files"] if f in EXTRA_FILES)
    path.write_text(f"""<!doctype html>
<html><head><meta charset="utf-8"><title>{html.escape(s.name)}: {verdict}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}
td{{padding:2px 8px}} .passed td:first-child{{color:green}}
.failed td:first-child{{color:#c00;font-weight:bold}} .skipped td:first-child{{color:gray}}
img{{max-width:100%}}</style></head><body>
<h1>{html.escape(s.name)}: {verdict}</h1>
<p>{html.escape(s.description)}</p>
<p>{result.mode} run of {summary['simulated_s']:.1f} s in {result.wall_time:.1f} s of wall time;
source <code>{html.escape(s.source)}</code>; also <a href="summary.json">summary.json</a>,
<a href="junit.xml">junit.xml</a>, <a href="trace.csv">trace.csv</a>{logs}.</p>
<table>{rows}</table>
{images}
</body></html>
""", encoding="utf-8")


# -- plots -------------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_all(result: RunResult, out: Path) -> None:
    plt = _pyplot()
    trace, events = result.trace, result.events
    title = f"{result.scenario.name} ({result.mode})"
    for name, fn in (("trajectory.png", plot_trajectory), ("velocities.png", plot_velocities),
                     ("battery.png", plot_battery), ("status.png", plot_status)):
        fig = fn(trace, events, title)
        fig.savefig(out / name, dpi=100)
        plt.close(fig)


def plot_trajectory(trace: Trace, events: list[tuple[float, str]], title: str) -> Any:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9.5, 6.5), layout="constrained")
    lines = (("truth", "ground truth", "black", "-", 2.0),
             ("raw", "/odom_raw (wheel odometry)", "tab:orange", "--", 1.5),
             ("ekf", "/odom (EKF: wheels + gyro)", "tab:blue", "-", 1.2))
    for prefix, label, color, style, width in lines:
        x, y = trace[f"{prefix}_x"], trace[f"{prefix}_y"]
        ok = np.isfinite(x) & np.isfinite(y)
        if not ok.any():
            continue
        err = ""
        if prefix != "truth" and trace.has("truth_x"):
            e = math.hypot(x[ok][-1] - trace["truth_x"][ok][-1],
                           y[ok][-1] - trace["truth_y"][ok][-1])
            err = f" (end error {e * 100:.1f} cm)"
        ax.plot(x[ok], y[ok], style, color=color, lw=width, label=label + err)
        ax.plot(x[ok][-1], y[ok][-1], "o", color=color, ms=5)
    if trace.has("truth_x"):
        ok = np.isfinite(trace["truth_x"])
        ax.plot(trace["truth_x"][ok][0], trace["truth_y"][ok][0], "s", color="green", ms=8,
                label="start")
    elif trace.has("raw_x"):
        ok = np.isfinite(trace["raw_x"])
        ax.plot(trace["raw_x"][ok][0], trace["raw_y"][ok][0], "s", color="green", ms=8,
                label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.4)
    _legend_outside(ax, fontsize=9)
    ax.set_title(f"{title}: trajectory")
    return fig


def _legend_outside(ax: Any, fontsize: int = 8) -> Any:
    """The legend to the right of the axes, where it cannot cover data (constrained layout
    makes room for it)."""
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                     fontsize=fontsize)


def _events(axes: Any, events: list[tuple[float, str]]) -> None:
    """Dotted vertical lines at the timeline's events, labelled on the top axis."""
    if not events:
        return
    for ax in axes:
        for t, _ in events:
            ax.axvline(t, color="gray", ls=":", lw=0.8)
    top = axes[0]
    groups: list[tuple[float, list[str]]] = []
    for t, what in events:  # events close together share one label
        if groups and t - groups[-1][0] < 0.3:
            groups[-1][1].append(what)
        else:
            groups.append((t, [what]))
    for t, whats in groups:
        top.annotate("; ".join(whats), (t, 1.0), xycoords=("data", "axes fraction"),
                     xytext=(2, 2), textcoords="offset points", rotation=40, fontsize=7,
                     ha="left", va="bottom", color="dimgray")


def plot_velocities(trace: Trace, events: list[tuple[float, str]], title: str) -> Any:
    plt = _pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, layout="constrained")
    t = trace["t"]
    for ax, (key, unit, name) in zip(axes, (("v", "m/s", "linear"), ("w", "rad/s", "angular")),
                                     strict=True):
        ax.step(t, trace[f"cmd_{key}"], where="post", color="gray", lw=1.2, label="commanded")
        if trace.has(f"truth_{key}"):
            ax.plot(t, trace[f"truth_{key}"], color="black", lw=1.6, label="true")
        ax.plot(t, trace[f"meas_{key}"], color="tab:blue", lw=1.0, label="measured (MotionState)")
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(True, alpha=0.4)
        _legend_outside(ax)
    axes[-1].set_xlabel("t [s]")
    _events(axes, events)
    fig.suptitle(f"{title}: velocities")
    return fig


def plot_battery(trace: Trace, events: list[tuple[float, str]], title: str) -> Any:
    plt = _pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True, layout="constrained")
    t = trace["t"]
    ax = axes[0]
    if trace.has("soc"):
        ax.step(t, trace["soc"], where="post", color="tab:green", label="BmsPack Soc (integer)")
    if trace.has("capacity_soc"):
        ax.plot(t, trace["capacity_soc"], color="tab:blue", lw=1.2,
                label="BmsCapacity remain/full")
    if trace.has("pack_soc"):
        ax.plot(t, trace["pack_soc"], color="black", ls="--", lw=1.0, label="pack model (exact)")
    ax.set_ylabel("SOC [%]")
    ax.grid(True, alpha=0.4)
    if trace.has("soc") or trace.has("pack_soc") or trace.has("capacity_soc"):
        _legend_outside(ax)
    else:
        ax.text(0.5, 0.5, "no battery frames", transform=ax.transAxes, ha="center")
    ax = axes[1]
    ax.plot(t, trace["voltage"], color="tab:red", label="voltage [V]")
    ax.set_ylabel("voltage [V]", color="tab:red")
    ax.grid(True, alpha=0.4)
    ax2 = ax.twinx()
    ax2.plot(t, trace["current"], color="tab:purple", lw=1.0)
    ax2.set_ylabel("current [A] (+ charging)", color="tab:purple")
    axes[-1].set_xlabel("t [s]")
    _events(axes, events)
    fig.suptitle(f"{title}: battery")
    return fig


def _segments(t: np.ndarray, on: np.ndarray) -> list[tuple[float, float]]:
    """(start, width) of the runs where ``on`` holds, each sample holding until the next."""
    out: list[tuple[float, float]] = []
    if not len(t):
        return out
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.05
    start: float | None = None
    for i, flag in enumerate(on):
        if flag and start is None:
            start = float(t[i])
        elif not flag and start is not None:
            out.append((start, float(t[i]) - start))
            start = None
    if start is not None:
        out.append((start, float(t[-1]) + step - start))
    return out


def plot_status(trace: Trace, events: list[tuple[float, str]], title: str) -> Any:
    plt = _pyplot()
    codes = trace["status"].astype(np.int64) if len(trace) else np.zeros(0, dtype=np.int64)
    seen = [b for b in StatusBit if (codes & int(b)).any()]
    rows: list[tuple[str, np.ndarray]] = [(str(b.name), (codes & int(b)) != 0) for b in seen]
    ready = LINK_STATES.index("ready")
    link = trace["link"]
    if len(trace) and (link != ready).any():
        # not a StatusCode bit: the driver's view of the link, on the same time axis
        rows.append(("(driver link not ready)", link != ready))
    height = 2.2 + 0.32 * max(len(rows), 1)
    fig, axes = plt.subplots(2, 1, figsize=(10, height + 2.0), sharex=True, layout="constrained",
                             gridspec_kw={"height_ratios": [height, 2.0]})
    t = trace["t"]
    ax = axes[0]
    for row, (_, on) in enumerate(rows):
        ax.broken_barh(_segments(t, on), (row - 0.35, 0.7), color=f"C{row % 10}")
    ax.set_yticks(range(len(rows)), [name for name, _ in rows], fontsize=8)
    ax.set_ylim(-0.7, max(len(rows), 1) - 0.3)
    ax.invert_yaxis()
    if not rows:
        ax.text(0.5, 0.5, "StatusCode stayed 0", transform=ax.transAxes, ha="center")
    ax.grid(True, axis="x", alpha=0.4)
    ax.set_ylabel("StatusCode bits set")
    ax = axes[1]
    ax.step(t, trace["robot_state"], where="post", color="black")
    ax.set_yticks(range(len(ROBOT_STATES)), ROBOT_STATES, fontsize=8)
    ax.set_ylim(-0.5, len(ROBOT_STATES) - 0.5)
    ax.set_ylabel("robot state")
    ax.grid(True, alpha=0.4)
    axes[-1].set_xlabel("t [s]")
    _events(axes, events)
    fig.suptitle(f"{title}: StatusCode and states")
    return fig
