"""Rows and timing helpers shared by the benchmark modules."""

from __future__ import annotations

import statistics
import subprocess
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass


@dataclass(frozen=True)
class Row:
    group: str
    name: str
    value: float
    unit: str
    note: str = ""


def best_rate(fn: Callable[[], int], repeat: int = 5) -> float:
    """Operations per second: the best of ``repeat`` runs of ``fn`` (which returns its count)."""
    rates = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        n = fn()
        rates.append(n / (time.perf_counter() - t0))
    return max(rates)


def percentile(values: list[float], p: float) -> float:
    if not values:
        return float("nan")
    if len(values) == 1:
        return values[0]
    return statistics.quantiles(values, n=1000, method="inclusive")[max(0, int(p * 10) - 1)]


def stop_processes(procs: Iterable[subprocess.Popen[str]], timeout: float = 15.0) -> None:
    """SIGTERM each still running process in turn (give them in stopping order, e.g. workers
    before the scheduler they would wait for), wait ``timeout`` [s] for it, then SIGKILL."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
        try:
            p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
