"""A soak of the real-time robot: RSS per part over a long run (issue 22 item 23).

    .venv/bin/python -m benchmarks.soak_robot --minutes 60            # the hour of the issue
    .venv/bin/python -m benchmarks.soak_robot --minutes 10 --goals    # with move_base goals

Starts ``lowerbase robot`` on a ROS master of its own (a free loopback port), optionally runs
``examples/sim_goals.py`` against it over and over (move_base goals and a transport task, the
vendor's interface only), and samples every part's resident set size from /proc every
``--every`` s. Prints one row per part: RSS at the first sample after start-up, at the end,
the maximum, and the growth in MB per hour (a least-squares slope over the second half of the
run, after the start-up's allocations); ``--csv FILE`` writes every sample. Not part of
``make bench`` (an hour); docs/benchmarks.md says how to run it.
"""

from __future__ import annotations

import argparse
import csv
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("world", "emulate", "driver", "navigation", "tasks")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _descendants(pid: int) -> list[int]:
    kids: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        kids.setdefault(ppid, []).append(int(entry.name))
    out, todo = [], [pid]
    while todo:
        for child in kids.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def _part(pid: int) -> str | None:
    """Which part a process is (the `-m lowerbase PART` of its command line), None if none."""
    try:
        argv = (Path("/proc") / str(pid) / "cmdline").read_bytes().split(b"\0")
    except OSError:
        return None
    words = [a.decode(errors="replace") for a in argv]
    if "lowerbase.robot.guard" in words:
        return None  # the guard's own small process: the part is its child
    for i, word in enumerate(words[:-1]):
        if word == "lowerbase" and words[i + 1] in PARTS:
            return words[i + 1]
    return None


def _rss_mb(pid: int) -> float:
    try:
        for line in (Path("/proc") / str(pid) / "status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def sample(robot: int) -> dict[str, float]:
    rss: dict[str, float] = {}
    for pid in _descendants(robot):
        part = _part(pid)
        if part is not None:
            rss[part] = rss.get(part, 0.0) + _rss_mb(pid)
    return rss


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.soak_robot")
    p.add_argument("--minutes", type=float, default=60.0)
    p.add_argument("--every", type=float, default=10.0, help="seconds between samples")
    p.add_argument("--map", default="warehouse")
    p.add_argument("--goals", action="store_true", help="run examples/sim_goals.py throughout")
    p.add_argument("--csv", metavar="FILE", help="write every sample")
    args = p.parse_args(argv)
    env = {**os.environ, "ROS_MASTER_URI": f"http://localhost:{_free_port()}",
           "ROS_IP": "127.0.0.1"}
    robot = subprocess.Popen([sys.executable, "-m", "lowerbase", "robot", "--map", args.map],
                             env=env, cwd=ROOT, stdout=subprocess.PIPE, text=True,
                             start_new_session=True)
    assert robot.stdout is not None
    for line in robot.stdout:
        print(line.rstrip(), file=sys.stderr)
        if "ready on ROS master" in line:
            break
    else:
        print("soak: the robot did not start", file=sys.stderr)
        return 1
    client: subprocess.Popen[bytes] | None = None
    rows: list[tuple[float, dict[str, float]]] = []
    t0 = time.monotonic()
    try:
        while time.monotonic() - t0 < args.minutes * 60.0 and robot.poll() is None:
            if args.goals and (client is None or client.poll() is not None):
                client = subprocess.Popen(
                    [sys.executable, str(ROOT / "examples" / "sim_goals.py"), "--goals", "10",
                     "--seed", str(len(rows))], env=env, cwd=ROOT,
                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            rows.append((time.monotonic() - t0, sample(robot.pid)))
            time.sleep(args.every)
    finally:
        if client is not None and client.poll() is None:
            client.terminate()
        os.killpg(robot.pid, signal.SIGINT)
        robot.wait(60)
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t_s", *PARTS])
            for t, rss in rows:
                w.writerow([f"{t:.1f}", *(f"{rss.get(k, float('nan')):.1f}" for k in PARTS)])
    print("| part | RSS start [MB] | RSS end [MB] | max [MB] | growth [MB/h] |")
    print("|---|---|---|---|---|")
    for part in PARTS:
        got = [(t, r[part]) for t, r in rows if part in r]
        if len(got) < 4:
            print(f"| {part} | n/a | n/a | n/a | n/a |")
            continue
        half = got[len(got) // 2:]
        ts, mb = np.array([t for t, _ in half]), np.array([m for _, m in half])
        slope = float(np.polyfit(ts, mb, 1)[0]) * 3600.0
        print(f"| {part} | {got[1][1]:.0f} | {got[-1][1]:.0f} | {max(m for _, m in got):.0f} "
              f"| {slope:+.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
