"""The campaign report: ``index.html`` with the pass rate per expectation, every failing run
with its replay command, and one plot per varied value (``vary-N.png``): the report's metric
over that value, passing and failing runs apart, the threshold as a line, and the share of
failing runs per bin below it (where does it break)."""

from __future__ import annotations

import html
import json
import math
import shlex
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lowerbase.campaign.execute import EXPECT
from lowerbase.campaign.spec import Campaign, Variation

BINS = 10


def replay_command(campaign_arg: str, index: int) -> str:
    return f"lowerbase campaign replay {shlex.quote(campaign_arg)} --run {index}"


def pass_rates(rows: Sequence[Mapping[str, Any]]) -> list[tuple[str, int, int]]:
    """(expectation, passed, scored) in column order; runs without it are not scored."""
    names: list[str] = []
    for row in rows:
        names += [k for k in row if k.startswith(EXPECT) and k not in names]
    out = []
    for name in names:
        scored = [row[name] for row in rows if row.get(name) is not None]
        out.append((name[len(EXPECT):], sum(bool(v) for v in scored), len(scored)))
    return out


def _number(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        return None
    return float(v)


def plot_variation(v: Variation, rows: Sequence[Mapping[str, Any]], metric: str,
                   threshold: float | None, path: Path) -> bool:
    """The plot of ``v`` (numbers: the metric over them and the failed share per bin;
    other values: the failed share per value). False when there are no rows."""
    if not rows:
        return False
    from lowerbase.reports.wheeled import _pyplot

    plt = _pyplot()
    xs = [_number(r.get(v.key)) for r in rows]
    if any(x is None for x in xs):
        labels = [json.dumps(r.get(v.key)) for r in rows]
        names = list(dict.fromkeys(labels))
        share = [sum(1 for lab, r in zip(labels, rows, strict=True)
                     if lab == n and not r.get("passed")) / labels.count(n) for n in names]
        fig, ax = plt.subplots(figsize=(7, 3.5))
        ax.bar(range(len(names)), share, color="tab:red", alpha=0.6, edgecolor="k", lw=0.5)
        ax.set_xticks(range(len(names)), [f"{n}\n({labels.count(n)} runs)" for n in names],
                      fontsize=8)
        ax.set_ylim(0, 1)
        ax.set_ylabel("failed share")
        ax.set_title(f"{v.key}: {v.describe()}", fontsize=10)
        ax.grid(alpha=0.3, axis="y")
        fig.tight_layout()
        fig.savefig(path, dpi=90)
        plt.close(fig)
        return True
    x = np.array(xs, dtype=float)
    ok = np.array([bool(r.get("passed")) for r in rows])
    y = np.array([_number(r.get(metric)) if _number(r.get(metric)) is not None else np.nan
                  for r in rows], dtype=float)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True,
                                      gridspec_kw={"height_ratios": [3, 1.3]})
    if metric and np.isfinite(y).any():
        top.scatter(x[ok], y[ok], s=14, color="tab:blue", label="passed")
        top.scatter(x[~ok], y[~ok], s=18, color="tab:red", marker="x", label="failed")
        if threshold is not None:
            top.axhline(threshold, color="k", ls="--", lw=1, label=f"threshold {threshold:g}")
        top.set_ylabel(metric)
        top.legend(fontsize=8, loc="best")
    else:
        top.text(0.5, 0.5, f"no metric {metric!r} in these runs", ha="center",
                 transform=top.transAxes)
    top.set_title(f"{v.key}: {v.describe()}", fontsize=10)
    top.grid(alpha=0.3)
    edges = np.unique(np.quantile(x, np.linspace(0, 1, BINS + 1)))
    if len(edges) < 2:
        edges = np.array([x.min() - 0.5, x.max() + 0.5])
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    rate = [float((~ok[which == b]).mean()) if (which == b).any() else 0.0
            for b in range(len(edges) - 1)]
    bottom.bar(edges[:-1], rate, width=np.diff(edges), align="edge", color="tab:red",
               alpha=0.6, edgecolor="k", lw=0.5)
    bottom.set_ylim(0, 1)
    bottom.set_ylabel("failed share")
    bottom.set_xlabel(v.key)
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "" if v is None else str(v)


def write_report(campaign: Campaign, rows: Sequence[Mapping[str, Any]], out: Path, *,
                 campaign_arg: str, interrupted: bool = False,
                 extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``index.html``, ``summary.json`` and the plots into ``out``; returns the summary."""
    rows = sorted(rows, key=lambda r: int(r["run"]))
    out.mkdir(parents=True, exist_ok=True)
    metric = campaign.metric
    plots = []
    for n, v in enumerate(campaign.variations):
        name = f"vary-{n}.png"
        if plot_variation(v, rows, metric, campaign.threshold, out / name):
            plots.append((v.key, name))
    failing = [r for r in rows if not r.get("passed")]
    rates = pass_rates(rows)
    summary: dict[str, Any] = {
        "campaign": campaign.name, "source": str(campaign.source), "runs": campaign.total,
        "finished": len(rows), "passed": len(rows) - len(failing), "failed": len(failing),
        "interrupted": interrupted, **(extra or {}),
        "expectations": [{"name": n, "passed": p, "scored": s} for n, p, s in rates],
        "failing_runs": [{"run": r["run"], "error": r.get("error") or None,
                          "replay": replay_command(campaign_arg, int(r["run"]))}
                         for r in failing],
        "plots": [p for _, p in plots],
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    (out / "index.html").write_text(_html(campaign, rows, failing, rates, plots, summary,
                                                    campaign_arg),
                                    encoding="utf-8")
    return summary


def _html(campaign: Campaign, rows: Sequence[Mapping[str, Any]],
          failing: Sequence[Mapping[str, Any]], rates: list[tuple[str, int, int]],
          plots: list[tuple[str, str]], summary: Mapping[str, Any], campaign_arg: str
          ) -> str:
    e = html.escape
    varied = [v.key for v in campaign.variations]
    head = (f"<h1>campaign {e(campaign.name)}</h1><p>{e(campaign.description)}</p>"
            f"<p>{summary['finished']} of {summary['runs']} runs finished"
            f"{' (interrupted)' if summary['interrupted'] else ''}: "
            f"<b>{summary['passed']} passed, {summary['failed']} failed</b>. "
            f"Table: <a href='results.csv'>results.csv</a>.</p>")
    vary = "".join(f"<li><code>{e(v.key)}</code>: {e(v.describe())}</li>"
                   for v in campaign.variations)
    rate_rows = "".join(
        f"<tr><td>{e(n)}</td><td>{p}/{s}</td><td>{100 * p / s if s else 0:.1f} %</td></tr>"
        for n, p, s in rates)
    figs = "".join(f"<h3>{e(k)}</h3><img src='{e(p)}' alt='{e(k)}'>" for k, p in plots)
    metric = campaign.metric
    cols = ["run", *varied, *([metric] if metric else []), "failed expectations / error",
            "replay"]
    fail_rows = []
    for r in failing:
        why = r.get("error") or "; ".join(k[len(EXPECT):] for k, v in r.items()
                                          if k.startswith(EXPECT) and v is False)
        cells = [r["run"], *(r.get(k) for k in varied), *([r.get(metric)] if metric else []),
                 why]
        fail_rows.append("<tr>" + "".join(f"<td>{e(_fmt(c))}</td>" for c in cells)
                         + f"<td><code>{e(replay_command(campaign_arg, int(r['run'])))}"
                           "</code></td></tr>")
    return ("<!doctype html><meta charset='utf-8'><title>campaign "
            f"{e(campaign.name)}</title><style>body{{font-family:sans-serif;margin:2em}}"
            "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px;"
            "font-size:13px}</style>" + head + f"<h2>Varied</h2><ul>{vary}</ul>"
            "<h2>Pass rate per expectation</h2><table><tr><th>expectation</th><th>passed"
            f"</th><th>rate</th></tr>{rate_rows}</table>"
            f"<h2>Where it breaks</h2><p>Metric <code>{e(metric or '(none)')}</code> over "
            "each varied value; below, the share of failing runs per bin.</p>" + figs +
            f"<h2>Failing runs ({len(failing)})</h2><table><tr>" +
            "".join(f"<th>{e(c)}</th>" for c in cols) + "</tr>" + "".join(fail_rows) +
            "</table>")
