"""A campaign through `--scheduler` on a real `dask scheduler` and two `dask worker`
processes on 127.0.0.1; one worker is killed mid-campaign and the table is still whole."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

import lowerbase
from benchmarks.common import stop_processes
from lowerbase.campaign.engine import open_client, quiet_dask
from lowerbase.campaign.execute import run_one
from lowerbase.campaign.plan import load_campaign, plan_run
from lowerbase.campaign.table import read_csv
from lowerbase.cli import main
from tests.conftest import free_tcp_port

CAMPAIGN = """
[campaign]
name = "killed"
scenario = "loop"
runs = 12
seed = 3
keep_expect = false
[vary]
"profile.truth.left_radius_error" = { uniform = [-0.02, 0.02] }
[[expect]]
kind = "pose"
estimate = "odom"
within = 0.05
"""


def _dask(*args: str) -> list[str]:
    script = Path(sys.executable).parent / "dask"
    return [str(script), *args] if script.exists() else [sys.executable, "-m", "dask", *args]


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """(scheduler address, the two worker processes)."""
    env = dict(os.environ)  # the workers import this checkout's lowerbase
    root = str(Path(lowerbase.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    info = tmp_path / "scheduler.json"
    logs = [(tmp_path / f"dask-{i}.log").open("wb") for i in range(3)]
    procs = [subprocess.Popen(_dask("scheduler", "--host", "127.0.0.1", "--port", "0",
                                    "--no-dashboard", "--scheduler-file", str(info)),
                              env=env, stdout=logs[0], stderr=subprocess.STDOUT)]
    try:
        deadline = time.monotonic() + 60
        while not info.exists() or not info.read_text().strip():
            assert procs[0].poll() is None, "dask scheduler exited"
            assert time.monotonic() < deadline, "dask scheduler did not start"
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        workers = [subprocess.Popen(_dask("worker", address, "--nthreads", "1",
                                          "--no-nanny", "--host", "127.0.0.1",
                                          "--no-dashboard"),
                                    env=env, stdout=logs[i], stderr=subprocess.STDOUT)
                   for i in (1, 2)]
        procs += workers
        yield address, workers
    finally:  # workers first, then the scheduler they would wait for
        stop_processes(reversed(procs))
        for f in logs:
            f.close()


@pytest.mark.process
def test_a_killed_worker_costs_no_row(tmp_path: Path,
                                      cluster: tuple[str, list[subprocess.Popen[bytes]]]
                                      ) -> None:
    address, workers = cluster
    with quiet_dask(), open_client(address) as client:
        client.wait_for_workers(2, timeout=60)
    path = tmp_path / "killed.toml"
    path.write_text(CAMPAIGN, encoding="utf-8")
    out = tmp_path / "out"
    killed = threading.Event()

    def kill_after_first_row() -> None:  # runs.jsonl gets each row as it arrives
        rows = out / "runs.jsonl"
        while not (rows.exists() and rows.read_text().strip()):
            if workers[0].poll() is not None or done.is_set():
                return
            time.sleep(0.02)
        workers[0].send_signal(signal.SIGKILL)
        killed.set()

    done = threading.Event()
    killer = threading.Thread(target=kill_after_first_row)
    killer.start()
    try:
        code = main(["campaign", "run", str(path), "--scheduler", address, "--out", str(out)])
    finally:
        done.set()
        killer.join()
    assert killed.is_set() and workers[0].wait(timeout=10) == -signal.SIGKILL
    assert code in (0, 1)
    rows = read_csv(out / "results.csv")
    assert [r["run"] for r in rows] == list(range(12))
    assert all(r["error"] is None for r in rows), [r["error"] for r in rows]
    assert all(isinstance(r["odom_error_m"], float) for r in rows)
    # the same runs in this process give the same table
    campaign = load_campaign(path)
    for r in rows[:3]:
        local = run_one(plan_run(campaign, int(r["run"])))
        assert r["odom_error_m"] == pytest.approx(local["odom_error_m"], abs=1e-6)


@pytest.mark.process
def test_no_scheduler_is_one_error_line(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN, encoding="utf-8")
    address = f"tcp://127.0.0.1:{free_tcp_port()}"
    code = main(["campaign", "run", str(path), "--scheduler", address,
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 1
    assert f"--scheduler {address}: nothing listens there" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("address", "says"), [
    ("http://127.0.0.1:8786", "unknown address scheme 'http'"),
    ("127.0.0.1:8786", "Must include protocol"),
    ("tcp://127.0.0.1:99999", "port 99999 is out of range"),
    ("tcp://nohost.invalid:8786", "unknown host 'nohost.invalid'")])
def test_a_bad_scheduler_address_is_one_line_at_once(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], address: str, says: str) -> None:
    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN, encoding="utf-8")
    code = main(["campaign", "run", str(path), "--scheduler", address,
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and says in err[-1] and "e.g. tcp://127.0.0.1:8786" in err[-1], err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("args", "says"), [
    (["--workers", "0"], "argument --workers: '0': must be 1 or more"),
    (["--workers", "-2"], "argument --workers: '-2': must be 1 or more"),
    (["--runs", "5-2"], "--runs 5-2: A-B with A <= B, e.g. 2-5")])
def test_bad_workers_and_runs_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                           args: list[str], says: str) -> None:
    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN, encoding="utf-8")
    try:
        code = main(["campaign", "run", str(path), *args, "--out", str(tmp_path / "out")])
    except SystemExit as e:  # argparse's own refusal
        code = int(e.code or 0)
    err = capsys.readouterr().err.strip().splitlines()
    assert code in (1, 2) and says in err[-1], err
    assert not (tmp_path / "out").exists()
