"""Scenario benchmarks: the scenario library and ``make demo``'s scenario on the simulated clock.

Every scenario of the library (scenarios/*.toml, what ``lowerbase scenario list`` shows) runs
through ``lowerbase.scenarios.runner.run_simulated``: the emulated MCU and the driver core in a
SimLoop, the runner's timeline, trace sampling and expectations (no report, no plots). Rows:
the library's total wall time and speed in x real time, the demo scenario (scenarios/demo.toml,
which ``make demo`` runs over a bus in real time) on the simulated clock, and the set-up part
(building the chassis: profile, MCU, IMU, BMS) per scenario. Each row is the best of a few
repeats; all expectations must pass.

``python -m benchmarks.bench_scenarios [--quick]`` prints the rows.
"""

from __future__ import annotations

import sys
import time

from benchmarks import cli_runs
from benchmarks.common import Row


def _run_library(repeat: int) -> dict[str, tuple[float, float, float, bool]]:
    """name -> (simulated s, best wall s of the whole run, best set-up wall s, passed)."""
    from lowerbase.scenarios.catalog import library
    from lowerbase.scenarios.runner import SimHarness, run_scenario
    from lowerbase.scenarios.wheeled import load_scenario

    out: dict[str, tuple[float, float, float, bool]] = {}
    for name, path in library().items():
        scenario = load_scenario(path)
        best_wall = best_setup = float("inf")
        passed = True
        for _ in range(repeat):
            t0 = time.perf_counter()
            harness = SimHarness(scenario)
            t1 = time.perf_counter()
            try:
                result = run_scenario(scenario, harness)
            finally:
                harness.close()
            t2 = time.perf_counter()
            best_wall, best_setup = min(best_wall, t2 - t0), min(best_setup, t1 - t0)
            passed = passed and result.passed
        out[name] = (scenario.duration, best_wall, best_setup, passed)
    return out


def run(quick: bool = False) -> list[Row]:
    runs = _run_library(1 if quick else 3)
    sim = sum(r[0] for r in runs.values())
    wall = sum(r[1] for r in runs.values())
    setup = sum(r[2] for r in runs.values())
    failed = [name for name, r in runs.items() if not r[3]]
    verdict = "all expectations passed" if not failed else f"FAILED: {', '.join(failed)}"
    rows = [
        Row("scenarios", "library on the simulated clock, total", wall, "s wall",
            f"{len(runs)} scenarios, {sim:.0f} s simulated; {verdict}"),
        Row("scenarios", "library on the simulated clock, speed", sim / wall, "x real time",
            "set-up included; runner + trace + expectations, no report"),
        Row("scenarios", "chassis set-up per scenario", setup / len(runs) * 1e3, "ms",
            "SimHarness: profile, MCU, IMU, BMS, driver core"),
    ]
    demo = runs.get("demo")
    if demo is not None:
        rows += [Row("scenarios", "demo scenario on the simulated clock", demo[1], "s wall",
                     f"scenarios/demo.toml, {demo[0]:.0f} s simulated ({demo[0] / demo[1]:.0f}x); "
                     "make demo runs it over a bus in real time")]
    slowest = max(runs.items(), key=lambda kv: kv[1][1] / kv[1][0])
    rows.append(Row("scenarios", f"slowest per simulated second: {slowest[0]}",
                    slowest[1][0] / slowest[1][1], "x real time", ""))
    return rows + cli_rows(60.0 if quick else 600.0)


def cli_rows(seconds: float) -> list[Row]:
    """``lowerbase scenario run`` as users run it, in a child process, by its CPU time (issue
    22 item 25): the library's loop lengthened to ``seconds``, with its default MCAP recording
    and with --no-mcap."""
    from lowerbase.scenarios.catalog import library

    path = library()["loop"]
    rows = []
    for label, extra in (("default (run.mcap)", ()), ("--no-mcap", ("--no-mcap",))):
        run = cli_runs.scenario(path, seconds, extra)
        rows.append(Row("scenarios", f"CLI scenario run, loop {seconds:g} s, {label}",
                        run.factor, "x real time",
                        f"`python -m lowerbase scenario run` in a child process, by its CPU "
                        f"time, start-up ({run.startup_cpu:.1f} s CPU: imports, set-up, the "
                        f"report) subtracted; {run.factor_with_startup:.0f}x with it"))
    return rows


if __name__ == "__main__":
    from benchmarks.__main__ import table

    print(table(run(quick="--quick" in sys.argv)))
