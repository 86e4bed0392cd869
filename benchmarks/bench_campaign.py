"""Campaigns on Dask (docs/campaigns.md).

* overhead: 200 library scenario runs (loop, wheel_slip, estop, watchdog, 50 each, a wheel's
  radius error varied) one after another in this process, then as a campaign on a LocalCluster
  of 2 worker processes; overhead = campaign time / (sum of single-run times / 2), with and
  without starting the cluster. Target: at most 1.15. Beside it, the same runs on 2 plain
  processes of a multiprocessing pool (no Dask): what this host gives two runs at once, so
  the overhead splits into the host's share and Dask's. The same for 200 runs of a mix of the
  library's kinds (:data:`MIX`: chassis, world, legged, tasks; 20 each of 10 scenarios).
* scaling: `dask scheduler` and 1, 2, 4 `dask worker` processes on 127.0.0.1 started here;
  the same runs through the scheduler; runs/s per size, and whether the tables (wall times
  aside) are identical on 1 and 4 workers.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from benchmarks.common import Row, stop_processes

CAMPAIGN = """
[campaign]
name = "bench"
scenarios = ["loop", "wheel_slip", "estop", "watchdog"]
runs = {runs}
seed = 1
[vary]
"profile.truth.right_radius_error" = {{ uniform = [-0.02, 0.02] }}
"""
#: a mix of the library's kinds: six chassis scenarios, the warehouse with lidars and amcl, a
#: legged and a tasks scenario (each run its own seeds; trace/diagram, ~30 s a run, left out)
MIX = """
[campaign]
name = "bench-mix"
scenarios = ["loop", "wheel_slip", "estop", "watchdog", "encoder_fault", "bms_link_lost",
             "contact", "warehouse_localization", "legged_actuator_overtemp", "tasks/picking"]
runs = {runs}
seed = 1
"""


def _campaign(tmp: Path, runs: int, text: str = CAMPAIGN) -> Any:
    from lowerbase.campaign.plan import load_campaign

    path = tmp / f"bench-{runs}-{len(text)}.toml"
    path.write_text(text.format(runs=runs), encoding="utf-8")
    return load_campaign(path)


def _table(rows: dict[int, dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in rows[i].items() if k != "wall_s"} for i in sorted(rows)]


def _dask(*args: str) -> list[str]:
    script = Path(sys.executable).parent / "dask"
    return [str(script), *args] if script.exists() else [sys.executable, "-m", "dask", *args]


@contextmanager
def _cluster(workers: int, tmp: Path) -> Iterator[str]:
    """`dask scheduler` and ``workers`` single-threaded `dask worker` processes on loopback."""
    import lowerbase

    env = dict(os.environ)
    root = str(Path(lowerbase.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    info = tmp / f"scheduler-{workers}.json"
    quiet = {"env": env, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    procs = [subprocess.Popen(_dask("scheduler", "--host", "127.0.0.1", "--port", "0",
                                    "--no-dashboard", "--scheduler-file", str(info)),
                              **quiet)]  # type: ignore[call-overload]
    try:
        while not info.exists() or not info.read_text().strip():
            if procs[0].poll() is not None:
                raise RuntimeError("dask scheduler exited")
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        procs += [subprocess.Popen(_dask("worker", address, "--nthreads", "1", "--no-nanny",
                                         "--host", "127.0.0.1", "--no-dashboard"),
                                   **quiet)  # type: ignore[call-overload]
                  for _ in range(workers)]
        yield address
    finally:  # workers first, then the scheduler they would wait for
        stop_processes(reversed(procs))


_BARRIER: Any = None


def _warm_process(path: str, barrier: Any) -> None:
    """A plain pool process's initializer: the first run of each scenario (as a warm worker)."""
    global _BARRIER
    from lowerbase.campaign.execute import run_one
    from lowerbase.campaign.plan import load_campaign, plan_run

    _BARRIER = barrier
    c = load_campaign(Path(path))
    for k in range(len(c.scenarios)):
        run_one(plan_run(c, k * c.per_scenario))


def _meet(_: int) -> None:
    """Returns once both pool processes are here (both warmed: one such task each)."""
    _BARRIER.wait(timeout=600)


def two_plain_processes(path: Path, specs: list[Any]) -> float:
    """[s] the runs on 2 warmed processes of a multiprocessing pool (no Dask): what this host
    gives two runs at once, the baseline Dask's own overhead is measured against."""
    import multiprocessing as mp

    from lowerbase.campaign.execute import run_one

    ctx = mp.get_context("forkserver")
    barrier = ctx.Barrier(2)
    with ctx.Pool(2, initializer=_warm_process, initargs=(str(path), barrier)) as pool:
        pool.map(_meet, range(2), chunksize=1)
        t0 = time.perf_counter()
        pool.map(run_one, specs, chunksize=1)
        return time.perf_counter() - t0


def overhead(runs: int, tmp: Path, mix: bool = False) -> list[Row]:
    from lowerbase.campaign.engine import open_client, plan_runs, quiet_dask, run_campaign
    from lowerbase.campaign.execute import run_one
    from lowerbase.campaign.plan import plan_run

    c = _campaign(tmp, runs, MIX if mix else CAMPAIGN)
    for k in range(len(c.scenarios)):  # JIT caches warm, as a worker's first run finds them
        run_one(plan_run(c, k * c.per_scenario))
    single = 0.0
    for i in range(c.total):
        t0 = time.perf_counter()
        run_one(plan_run(c, i))
        single += time.perf_counter() - t0
    specs: dict[int, Any] = {}
    # as `lowerbase campaign run`: the cluster starts and its workers warm while the runs are
    # planned; then the runs (the planning is in the time with the start only)
    t0 = time.perf_counter()
    with quiet_dask(), open_client(workers=2, warm=True,
                                   meanwhile=lambda: specs.update(plan_runs(c))) as client:
        t1 = time.perf_counter()
        result = run_campaign(c, client, warm=False, specs=specs)
        t2 = time.perf_counter()
    assert len(result.rows) == c.total
    plain = two_plain_processes(c.source, [specs[i] for i in sorted(specs)])
    ideal = single / 2
    on_workers = sum(float(r["wall_s"]) for r in result.rows.values())
    note = f"{c.total} runs; sum of single runs {single:.1f} s, ideal on 2 = {ideal:.1f} s"
    tag = "mix of kinds: " if mix else ""
    return [
        Row("campaign", f"{tag}sum of single-run times", single, "s",
            f"{c.total} runs in 1 process"),
        Row("campaign", f"{tag}LocalCluster(2): runs only", t2 - t1, "s", note),
        Row("campaign", f"{tag}LocalCluster(2): overhead, runs only", (t2 - t1) / ideal, "x",
            "target <= 1.15"),
        Row("campaign", f"{tag}LocalCluster(2): overhead with cluster start", (t2 - t0) / ideal,
            "x", f"cluster start and warm-up {t1 - t0:.1f} s (the runs planned meanwhile)"),
        Row("campaign", f"{tag}2 plain processes (no Dask): runs", plain / ideal, "x",
            f"{plain:.1f} s: what this host gives two runs at once (multiprocessing pool)"),
        Row("campaign", f"{tag}LocalCluster(2) against 2 plain processes", (t2 - t1) / plain,
            "x", "Dask's own share of the overhead"),
        Row("campaign", f"{tag}LocalCluster(2): overhead vs the runs' times on the workers",
            (t2 - t1) / (on_workers / 2), "x",
            f"sum of wall_s on the workers {on_workers:.1f} s (a busy host slows the runs "
            "themselves; this is what Dask adds)"),
    ]


def scaling(runs: int, tmp: Path) -> list[Row]:
    from lowerbase.campaign.engine import open_client, quiet_dask, run_campaign, warm_workers

    c = _campaign(tmp, runs)
    rows: list[Row] = []
    tables: dict[int, list[dict[str, Any]]] = {}
    for n in (1, 2, 4):
        with _cluster(n, tmp) as address, quiet_dask(), open_client(address) as client:
            client.wait_for_workers(n, timeout=120)
            warm_workers(client)
            t0 = time.perf_counter()
            result = run_campaign(c, client, warm=False)
            dt = time.perf_counter() - t0
        tables[n] = _table(result.rows)
        rows.append(Row("campaign", f"dask scheduler + {n} worker(s)", c.total / dt, "runs/s",
                        f"{c.total} runs in {dt:.1f} s on {os.cpu_count()} cores"))
    same = tables[1] == tables[4]
    rows.append(Row("campaign", "tables identical on 1 and 4 workers", float(same), "bool",
                    "wall_s left out"))
    return rows


def fresh_overhead(runs: int, tmp: Path, mix: bool = False) -> list[Row]:
    """:func:`overhead` in a fresh interpreter, as `lowerbase campaign run` starts: its
    LocalCluster's forkserver warms up there (in this process a second campaign would fork
    from the one the first started, already warm)."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        return pool.submit(overhead, runs, tmp, mix).result()


def run(quick: bool = False) -> list[Row]:
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as d:
        tmp = Path(d)
        return (fresh_overhead(5 if quick else 50, tmp)
                + fresh_overhead(1 if quick else 20, tmp, mix=True)
                + scaling(2 if quick else 10, tmp))


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(r)
