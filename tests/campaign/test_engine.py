"""`lowerbase campaign run` on a LocalCluster of two processes, and `replay` of a run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

import lowerbase
from lowerbase.campaign.execute import run_one
from lowerbase.campaign.plan import load_campaign, plan_run
from lowerbase.campaign.table import WALL, read_csv
from lowerbase.cli import main

SMALL = """
[campaign]
name = "small"
scenario = "wheel_slip"
runs = 3
seed = 11
[vary]
"timeline.1.fraction" = { uniform = [0.0, 0.6] }
"profile.truth.right_radius_error" = { normal = [0.0, 0.01], min = -0.02, max = 0.02 }
[[expect]]
kind = "pose"
estimate = "odom"
within = 0.08
[report]
metric = "odom_error_m"
threshold = 0.08
"""


def _same(a: dict, b: dict) -> bool:
    return {k: v for k, v in a.items() if k not in WALL} == \
        {k: v for k, v in b.items() if k not in WALL}


@pytest.mark.process
def test_run_on_a_local_cluster_then_replay(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "small.toml"
    path.write_text(SMALL, encoding="utf-8")
    out = tmp_path / "out"
    code = main(["campaign", "run", str(path), "--workers", "2", "--out", str(out),
                 "--progress"])
    text = capsys.readouterr()
    assert code in (0, 1), text.err
    assert "3/3" in text.err and "done" in text.err  # the progress line
    rows = read_csv(out / "results.csv")
    assert [r["run"] for r in rows] == [0, 1, 2]
    assert all(r["error"] is None for r in rows)
    assert {"odom_error_m", "odom_error_p95_m", "soc_final",
            "expect: /odom within 0.08 m of the truth at the end"} <= set(rows[0])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["finished"] == 3 and len(summary["plots"]) == 2
    assert (out / "vary-0.png").stat().st_size > 1000
    assert "replay" in (out / "index.html").read_text() or summary["failed"] == 0
    # a row from a worker equals the same run in this process
    c = load_campaign(path)
    local = run_one(plan_run(c, 1))
    jsonl = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert _same(next(r for r in jsonl if r["run"] == 1), local)
    # replay: the same run with the full report and an MCAP
    rep = tmp_path / "replay"
    code = main(["campaign", "replay", str(path), "--run", "1", "--out", str(rep)])
    assert code == (0 if local["passed"] else 1)
    got = json.loads((rep / "summary.json").read_text())
    assert got["final"]["odom_error_m"] == pytest.approx(local["odom_error_m"], abs=1e-6)
    assert (rep / "run.mcap").stat().st_size > 0
    assert json.loads((rep / "run.json").read_text())["values"] == plan_run(c, 1).values


@pytest.mark.process
def test_ctrl_c_keeps_the_runs_that_finished(tmp_path: Path) -> None:
    """SIGINT to the process group (a terminal's Ctrl-C) after 3 rows: exit 130, the table
    and report of what finished, no traceback from the workers."""
    path = tmp_path / "long.toml"
    path.write_text(SMALL.replace("runs = 3", "runs = 200"), encoding="utf-8")
    out = tmp_path / "out"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(Path(lowerbase.__file__).resolve().parents[1]),
                    env.get("PYTHONPATH")) if p)
    proc = subprocess.Popen(
        [sys.executable, "-m", "lowerbase", "campaign", "run", str(path), "--workers", "2",
         "--out", str(out)], env=env, start_new_session=True, text=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    rows = out / "runs.jsonl"
    try:
        while not (rows.exists() and len(rows.read_text().splitlines()) >= 3):
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, stderr
    assert "INTERRUPTED" in stdout and "Traceback" not in stderr, stderr
    table = read_csv(out / "results.csv")
    assert 3 <= len(table) < 200
    assert json.loads((out / "summary.json").read_text())["interrupted"] is True


def _wanted_runs(dask_scheduler: Any) -> list[str]:
    """The runs a client still wants (run_on_scheduler passes ``dask_scheduler``)."""
    return sorted(str(k) for k, ts in dask_scheduler.tasks.items()
                  if str(k).startswith("lowerbase-run-") and ts.who_wants)


@pytest.mark.process
def test_an_interrupted_campaign_returns_once_the_scheduler_cancelled_the_rest(
        tmp_path: Path) -> None:
    """Ctrl-C (here raised by a row's callback) after 3 rows: run_campaign returns the 3 and
    by then the scheduler has dropped every other run; closing the client then logs nothing
    (it logged a CRITICAL traceback when the cancel was still on its way: CI's stderr)."""
    import logging

    from lowerbase.campaign.engine import open_client, quiet_dask, run_campaign

    path = tmp_path / "long.toml"
    path.write_text(SMALL.replace("runs = 3", "runs = 200"), encoding="utf-8")
    records: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(record)

    def stop_after_three(row: dict[str, Any]) -> None:
        if len(rows) == 2:
            raise KeyboardInterrupt
        rows.append(row)

    rows: list[dict[str, Any]] = []
    keep = Keep(level=logging.WARNING)
    logging.getLogger("distributed").addHandler(keep)
    try:
        with quiet_dask(), open_client(workers=2) as client:
            out = run_campaign(load_campaign(path), client, on_row=stop_after_three)
            wanted = client.run_on_scheduler(_wanted_runs)
    finally:
        logging.getLogger("distributed").removeHandler(keep)
    assert out.interrupted and len(out.rows) == 3
    # (the finished runs' futures go as run_campaign returns: they may be released already)
    assert [k for k in wanted if int(k.split("-")[2]) not in out.rows] == []
    assert [r.getMessage()[:80] for r in records] == []


def _worker_settings(dask_worker: Any) -> dict[str, Any]:
    """What a worker runs beside the campaign's runs (client.run passes ``dask_worker``)."""
    import dask

    return {"profile": "profile" in dask_worker.periodic_callbacks,
            "tick": dask.config.get("distributed.admin.tick.interval"),
            "memory": dask.config.get("distributed.worker.memory.monitor-interval")}


@pytest.mark.process
def test_local_cluster_workers_run_without_the_profiler_and_with_slow_monitors() -> None:
    from lowerbase.campaign.engine import LOCAL_CLUSTER_CONFIG, open_client, quiet_dask

    with quiet_dask(), open_client(workers=1) as client:
        got = list(client.run(_worker_settings).values())
    assert got == [{"profile": False,
                    "tick": LOCAL_CLUSTER_CONFIG["distributed.admin.tick.interval"],
                    "memory": LOCAL_CLUSTER_CONFIG["distributed.worker.memory.monitor-interval"]}]


def _worker_start() -> dict[str, Any]:
    kernel = sys.modules.get("lowerbase.firmware_model.lean_kernel")
    return {"preloaded": "lowerbase.campaign.prewarm" in sys.modules,
            "kernel loaded": bool(kernel is not None and kernel.period.signatures),
            "parent": os.getppid()}


@pytest.mark.process
def test_local_cluster_workers_are_forked_warm_from_one_forkserver() -> None:
    """Without the warm-up plugin, a worker has the kernels loaded as it starts: it was forked
    from the forkserver that warmed once (not spawned, nor a child of this process)."""
    from lowerbase.campaign.engine import open_client, quiet_dask

    with quiet_dask(), open_client(workers=2, warm=False) as client:
        got = list(client.run(_worker_start).values())
    assert [(g["preloaded"], g["kernel loaded"]) for g in got] == [(True, True)] * 2
    assert got[0]["parent"] == got[1]["parent"] != os.getpid()


@pytest.mark.process
def test_two_local_clusters_at_once_start_without_a_port_warning() -> None:
    import warnings

    from lowerbase.campaign.engine import open_client, quiet_dask

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        with quiet_dask(), open_client(workers=1) as a, open_client(workers=1) as b:
            ports = [c.scheduler_info()["services"]["dashboard"] for c in (a, b)]
    assert [str(w.message) for w in seen if "in use" in str(w.message)] == []
    assert len(set(ports)) == 2 and 8787 not in ports


FORKSERVER_EXIT = """
import atexit, multiprocessing.forkserver, sys
from lowerbase.campaign import engine
engine.FORKSERVER_PRELOAD = ("slow_preload",)
engine.start_forkserver()
if len(sys.argv) > 1:  # the at-exit stop, with a shorter patience
    atexit.unregister(engine.stop_forkserver)
    atexit.register(engine.stop_forkserver, float(sys.argv[1]))
print(multiprocessing.forkserver._forkserver._forkserver_pid, flush=True)
"""


@pytest.mark.process
@pytest.mark.parametrize(("preload", "patience"), [
    ("import time\ntime.sleep(3)\n", ()),
    ("import threading\nthreading.Event().wait()\n", ("0.5",))], ids=["slow", "stuck"])
def test_the_forkserver_has_gone_when_the_process_that_started_it_exits(
        tmp_path: Path, preload: str, patience: tuple[str, ...]) -> None:
    """A forkserver left to notice its parent's exit on its own holds the parent's stdout open
    for as long as it takes (here: a preload of a few seconds; a busy host's scheduling), so
    ``lowerbase campaign run | tee`` did not end with the CLI; it is stopped at exit, and one
    stuck in its preload is killed after a while, with a warning."""
    (tmp_path / "slow_preload.py").write_text(preload)
    proc = subprocess.Popen([sys.executable, "-c", FORKSERVER_EXIT, *patience],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(tmp_path)})
    assert proc.stdout is not None
    pid = int(proc.stdout.readline())
    assert proc.wait(timeout=120) == 0
    try:
        os.kill(pid, 0)
        alive = True
    except ProcessLookupError:
        alive = False
    assert proc.stdout.read() == ""  # at its end already
    assert proc.stderr is not None
    err = proc.stderr.read()
    proc.stdout.close()
    proc.stderr.close()
    assert not alive
    assert ("did not stop in 0.5 s; killed" in err) == bool(patience), err
