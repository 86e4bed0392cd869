"""One run of a campaign, on whichever worker gets it: build the varied scenario, run it on
the simulated clock with the same in-process runner as ``lowerbase scenario run`` (no report,
no MCAP), and return its table row."""

from __future__ import annotations

import contextlib
import logging
import math
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from lowerbase.campaign.plan import RunSpec, build_scenario

EXPECT = "expect: "  #: column prefix of an expectation's pass (True) / fail (False)
#: the row's fixed columns, before its varied values, expectations and metrics
HEAD = ("run", "scenario", "passed", "error")


def _r(x: float, digits: int = 6) -> float | None:
    return round(float(x), digits) if math.isfinite(x) else None


def _errors(truth_x: np.ndarray, truth_y: np.ndarray, x: np.ndarray, y: np.ndarray,
            name: str) -> dict[str, float | None]:
    """Final and 95th-percentile position error [m] of an estimate against the truth."""
    err = np.hypot(x - truth_x, y - truth_y)
    err = err[np.isfinite(err)]
    if not len(err):
        return {f"{name}_error_m": None, f"{name}_error_p95_m": None}
    return {f"{name}_error_m": _r(err[-1]), f"{name}_error_p95_m": _r(np.percentile(err, 95))}


def _wheeled(sc: Any) -> tuple[list[tuple[str, bool]], dict[str, Any]]:
    from lowerbase.scenarios.runner import SimHarness, run_scenario

    harness = SimHarness(sc)
    try:
        result = run_scenario(sc, harness, mode="simulated")
    finally:
        harness.close()
    tr = result.trace
    metrics: dict[str, Any] = {"sim_s": _r(tr.end, 3)}
    if len(tr) and tr.has("truth_x"):
        for name, prefix in (("odom", "ekf"), ("odom_raw", "raw")):
            if tr.has(f"{prefix}_x"):
                metrics.update(_errors(tr["truth_x"], tr["truth_y"], tr[f"{prefix}_x"],
                                       tr[f"{prefix}_y"], name))
        if tr.has("ekf_yaw"):
            d = tr["ekf_yaw"][-1] - tr["truth_yaw"][-1]
            metrics["odom_yaw_error_rad"] = _r(abs(math.remainder(d, math.tau)))
    if len(tr):
        metrics["soc_final"] = _r(tr["soc"][-1], 3)
        metrics["reboots"] = int(tr["reboots"][-1])
    outcomes = [(e.title(), o.status != "failed") for e, o in result.outcomes]
    return outcomes, metrics


def _tasks(sc: Any) -> tuple[list[tuple[str, bool]], dict[str, Any]]:
    from lowerbase.reports.tasks import columns
    from lowerbase.scenarios.tasks_run import run_tasks_scenario

    result = run_tasks_scenario(sc)
    metrics: dict[str, Any] = {}
    if result.samples:
        c = columns(result)
        metrics["sim_s"] = _r(c["t"][-1], 3)
        metrics.update(_errors(c["truth_x"], c["truth_y"], c["est_x"], c["est_y"],
                               "localization"))
        metrics["soc_final"] = _r(c["pack_soc"][-1], 3)
        metrics["driven_m"] = _r(np.hypot(np.diff(c["truth_x"]), np.diff(c["truth_y"])).sum(),
                                 3)
    if result.history:  # when robot_status last changed: the task logic settled
        metrics["task_time_s"] = _r(result.history[-1][0], 3)
    return [(e.title(), ok) for e, ok, _ in result.outcomes], metrics


def _legged(sc: Any) -> tuple[list[tuple[str, bool]], dict[str, Any]]:
    from lowerbase.scenarios.legged_run import run_legged_scenario

    result = run_legged_scenario(sc)
    tr = result.trace
    metrics: dict[str, Any] = {"sim_s": _r(tr.end, 3)}
    if len(tr):  # the driver's base position against the model's truth; the pack voltage
        metrics.update(_errors(tr["truth_x"], tr["truth_y"], tr["x"], tr["y"], "position"))
        metrics["voltage_final"] = _r(tr["voltage"][-1], 3)
    return [(e.title(), o.status != "failed") for e, o in result.outcomes], metrics


def _trace(sc: Any) -> tuple[list[tuple[str, bool]], dict[str, Any]]:
    from lowerbase.scenarios.trace import run_trace_scenario

    result = run_trace_scenario(sc)
    return ([(name, ok) for name, ok, _ in result.outcomes],
            {"sim_s": _r(result.sim_time, 3)})


RUNNERS = {"wheeled": _wheeled, "tasks": _tasks, "legged": _legged, "trace": _trace}

#: a second of driving: imports the runner and loads the wheeled numba kernels from their cache
WARM = {"scenario": {"name": "warm", "duration": 1.0},
        "timeline": [{"at": 0.1, "action": "twist", "linear": 0.3, "duration": 0.5}]}


def warm() -> None:
    """Make a fresh worker's first run as fast as its next (~5 s of imports and cache loads
    otherwise land in the first run's time)."""
    from lowerbase.scenarios.wheeled import scenario_from_dict

    with _quiet():
        _wheeled(scenario_from_dict(WARM, source="warm"))


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """A run's log records (link lost, faults) are not the campaign's output."""
    logger = logging.getLogger("lowerbase")
    saved = logger.level, logger.propagate
    logger.setLevel(logging.ERROR)
    logger.propagate = False
    try:
        yield
    finally:
        logger.setLevel(saved[0])
        logger.propagate = saved[1]


def run_one(spec: RunSpec) -> dict[str, Any]:
    """Run ``spec`` and return its row: run, scenario, passed, error, the varied values, one
    ``expect: TITLE`` column per expectation, the metrics and ``wall_s``. An exception of the
    run is its ``error`` (the run failed), not the worker's."""
    t0 = time.perf_counter()
    row: dict[str, Any] = {"run": spec.index, "scenario": spec.scenario, "passed": False,
                           "error": ""}
    row.update(spec.values)
    try:
        with tempfile.TemporaryDirectory(prefix="lowerbase-run-") as tmp, _quiet():
            sc = build_scenario(spec, Path(tmp))
            outcomes, metrics = RUNNERS[spec.kind](sc)
    except Exception as e:  # a run that raises is a failed run with its reason
        row["error"] = f"{type(e).__name__}: {e}".splitlines()[0][:300]
        outcomes, metrics = [], {}
    for title, ok in outcomes:
        row[f"{EXPECT}{title}"] = ok
    row["passed"] = not row["error"] and all(ok for _, ok in outcomes)
    row.update(metrics)
    row["wall_s"] = round(time.perf_counter() - t0, 4)
    return row
