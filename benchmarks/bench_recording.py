"""MCAP recording benchmarks: the cost of writing a run as MCAP, per simulated second.

The demo scenario (scenarios/demo.toml) runs on the simulated clock three ways: without any
recorder, with the MCAP recorder's driver topics and frames (``McapRecorder``: /odom,
/odom_raw, /tf, /imu/data_raw, battery, BMS, status, truth, /can/frames) and with the decoded
JSON signals on top (what ``lowerbase scenario run`` writes by default). Rows: the extra wall
time per simulated second for each, and the file size per simulated second. Best of a few
repeats, measured back to back.

``python -m benchmarks.bench_recording [--quick]`` prints the rows.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import Row


def _run(decoded: bool | None, path: Path) -> tuple[float, float]:
    """(wall s, simulated s) of the demo scenario; decoded None: no recorder."""
    from lowerbase.bench.runner import SimHarness, run_scenario
    from lowerbase.bench.scenario import library, load_scenario
    from lowerbase.recording.mcap_writer import McapRecorder

    scenario = load_scenario(library()["demo"])
    rec = McapRecorder(path, decoded=decoded) if decoded is not None else None
    t0 = time.perf_counter()
    harness = SimHarness(scenario, tap=rec)
    if rec is not None:
        rec.attach(harness.driver, harness.now, harness.truth)
    try:
        run_scenario(scenario, harness)
    finally:
        harness.close()
        if rec is not None:
            rec.close()
    return time.perf_counter() - t0, scenario.duration


def run(quick: bool = False) -> list[Row]:
    repeat = 1 if quick else 3
    best: dict[str, float] = {}
    size = 0
    sim = 1.0
    with tempfile.TemporaryDirectory(prefix="bench-recording-") as tmp:
        path = Path(tmp) / "run.mcap"
        for _ in range(repeat):  # interleaved: the three variants see the same load
            for key, decoded in (("none", None), ("ros1", False), ("all", True)):
                wall, sim = _run(decoded, path)
                best[key] = min(best.get(key, float("inf")), wall)
                if key == "all":
                    size = path.stat().st_size
    base = best["none"] / sim
    return [
        Row("recording", "demo scenario, no recorder", 1e3 * base, "ms wall per sim s",
            f"{sim:g} s simulated"),
        Row("recording", "MCAP: driver topics + truth + raw frames", 1e3 * (best["ros1"] / sim
                                                                           - base),
            "ms per sim s", "extra over no recorder"),
        Row("recording", "MCAP: + decoded signals (default)", 1e3 * (best["all"] / sim - base),
            "ms per sim s", "extra over no recorder"),
        Row("recording", "MCAP file size (default)", size / sim / 1e3, "kB per sim s",
            "zstd chunks"),
    ]


if __name__ == "__main__":
    from benchmarks.__main__ import table

    print(table(run(quick="--quick" in sys.argv)))
