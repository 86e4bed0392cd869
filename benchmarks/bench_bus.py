"""The bus at its limit: emulator and driver core with foreign traffic filling the bus.

Three processes on one udp_multicast bus (loopback, a free port of its own): ``lowerbase
emulate``, the driver core (``benchmarks.busload_proc driver``, listening as the ROS
node's BusLink does) driving a twist, and another device (``busload_proc foreign``) sending
classic 8-byte frames on IDs the catalog does not have at the bus's capacity (500 kbit/s, mean
stuffed frame length: protocol.busload) minus the emulator's and driver's own rate. Run once
idle and once with the foreign load, and reported side by side.
"""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from typing import Any

from benchmarks.bench_emulator import deviations, periodic_key
from benchmarks.busload_proc import cpu_seconds, run_queue_wait
from benchmarks.common import Row, percentile
from lowerbase.protocol.busload import mean_frame_bits
from lowerbase.protocol.codec import Codec, default_codec
from lowerbase.transport import free_loopback_port

GROUP = "239.74.163.99"
BITRATE = 500_000  #: chassis.dbc's Baudrate
START_TIMEOUT = 30.0


def _proc(*args: str, stderr: Any = subprocess.DEVNULL) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", *args], stdout=subprocess.PIPE,
                            stderr=stderr, stdin=subprocess.DEVNULL, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})


def _line(proc: subprocess.Popen[str], wanted: str) -> str:
    assert proc.stdout is not None
    while True:
        line = proc.stdout.readline()
        if not line:
            raise RuntimeError(f"{proc.args!r} exited before printing {wanted!r}")
        if wanted in line:
            return line


def _emulator_stats(stderr: str) -> dict[str, int]:
    """The counters of ``lowerbase emulate: stopped after T s; key n, key n`` (the clauses
    that are no counters, such as the time slipped on a busy host, are left out)."""
    line = next(ln for ln in reversed(stderr.splitlines()) if "stopped after" in ln)
    out = {}
    for item in line.split("; ", 1)[1].replace("; ", ", ").split(", "):
        key, _, value = item.rpartition(" ")
        if key and value.isdigit():
            out[key] = int(value)
    return out


class RunQueueSampler:
    """Every ``period`` s, a process' run and run-queue wait times [ns] summed over its threads
    (/proc/<pid>/task/*/schedstat), with the wall time (``time.time``, the clock of the kernel's
    receive stamps): what the process did while its frames were late."""

    def __init__(self, pid: int, period: float = 0.002) -> None:
        self.pid, self.period = pid, period
        self.samples: list[tuple[float, int, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            run = wait = 0
            try:
                for task in os.listdir(f"/proc/{self.pid}/task"):
                    with open(f"/proc/{self.pid}/task/{task}/schedstat", encoding="ascii") as f:
                        r, w, _ = f.read().split()
                    run, wait = run + int(r), wait + int(w)
            except (OSError, ValueError):  # the process (or a thread) is gone
                continue
            self.samples.append((time.time(), run, wait))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def between(self, t0: float, t1: float) -> tuple[float, float, float]:
        return usage_between(self.samples, t0, t1)


def usage_between(samples: list[tuple[float, int, int]], t0: float, t1: float
                  ) -> tuple[float, float, float]:
    """(run, run-queue wait, span) [s] between the last of ``samples`` (time, run ns, wait ns;
    in time order) at or before ``t0`` and the first at or after ``t1``; NaNs if the samples do
    not cover both."""
    before = [s for s in samples if s[0] <= t0]
    after = [s for s in samples if s[0] >= t1]
    if not before or not after:
        return (float("nan"),) * 3
    a, b = before[-1], after[0]
    return (b[1] - a[1]) / 1e9, (b[2] - a[2]) / 1e9, b[0] - a[0]


def _stop(proc: subprocess.Popen[str]) -> tuple[str, str]:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        return proc.communicate(timeout=15)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate()


def trial(seconds: float, foreign_rate: float, catalog_filter: bool = True) -> dict[str, Any]:
    """One run: emulator, foreign traffic (if ``foreign_rate``) and driver core, measured over
    ``seconds`` once the driver is ready (``catalog_filter`` False: the driver core listens
    to everything)."""
    port = str(free_loopback_port())
    bound = str(seconds + START_TIMEOUT + 10)  # every child ends by itself
    emu = _proc("lowerbase", "emulate", "-i", "udp_multicast", "-c", GROUP, "--bus-kwargs",
                f"port={port}", "hop_limit=0", "--duration", bound, stderr=subprocess.PIPE)
    procs = [emu]
    gen = drv = None
    with tempfile.NamedTemporaryFile(prefix="lowerbase-busload-", suffix=".json") as tmp:
        try:
            _line(emu, "lower computer on")
            if foreign_rate > 0:
                gen = _proc("benchmarks.busload_proc", "foreign", "--channel", GROUP,
                            "--port", port, "--rate", f"{foreign_rate:.1f}", "--duration", bound)
                procs.append(gen)
            drv = _proc("benchmarks.busload_proc", "driver", "--channel", GROUP,
                        "--port", port, "--duration", str(seconds), "--frames", tmp.name,
                        *([] if catalog_filter else ["--no-filter"]))
            procs.append(drv)
            _line(drv, "measuring")
            cpu0 = {p.pid: cpu_seconds(p.pid) for p in (emu, gen) if p is not None}
            wait0 = run_queue_wait(emu.pid)
            sampler = RunQueueSampler(emu.pid)
            drv_sampler = RunQueueSampler(drv.pid)
            driver = json.loads(_line(drv, "{"))
            cpu = {pid: cpu_seconds(pid) - c for pid, c in cpu0.items()}
            wait_emu = run_queue_wait(emu.pid) - wait0
            sampler.stop()
            drv_sampler.stop()
            in_gap = sampler.between(*driver["odom_max_gap_rx"])
            drv_in_gap = drv_sampler.between(*driver["odom_max_gap_wall"])
            drv.wait(timeout=15)
            foreign = json.loads(_stop(gen)[0]) if gen is not None else None
            emu_stats = _emulator_stats(_stop(emu)[1])
            with open(tmp.name, encoding="utf-8") as f:
                frames = json.load(f)
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
                    p.wait()
    return {"driver": driver, "frames": frames, "emulator": emu_stats, "foreign": foreign,
            "cpu_emulator": cpu[emu.pid] / seconds, "wait_emulator": wait_emu,
            "emulator_in_gap": in_gap, "driver_in_gap": drv_in_gap, "load": os.getloadavg()[0],
            "cpu_foreign": cpu[gen.pid] / seconds if gen is not None else float("nan")}


def lost_from_lower(codec: Codec, frames: list[list[Any]]) -> tuple[int, int, int]:
    """(frames lost by the rolling counters, by the counts, frames received) of the lower
    computer's periodic streams as the driver received them. Counters run per message (both
    wheels share one per cycle: per wheel; LedState's rows each take the next one); the count
    of a stream is compared with its span over its cycle (a stall caught up later by a burst
    loses nothing)."""
    counters: dict[str, list[int]] = defaultdict(list)
    stamps: dict[str, list[float]] = defaultdict(list)
    for stamp, frame_id, hexdata in frames:
        data = bytes.fromhex(hexdata)
        key = periodic_key(codec, frame_id, data)
        if key is None:
            continue
        stamps[key].append(stamp)
        values = codec.message(frame_id).decode(data)
        if "Counter" in values:
            counters[key if key.startswith("WheelFeedback") else key.split("/")[0]].append(
                int(values["Counter"]))
    by_counter = sum((b - a - 1) % 16 for seq in counters.values()
                     for a, b in itertools.pairwise(seq))
    by_count = sum(max(round((stamps[key][-1] - stamps[key][0]) / cycle) + 1
                       - len(stamps[key]), 0) for key, cycle, _ in deviations(codec, stamps))
    return by_counter, by_count, sum(len(s) for s in stamps.values())


def jitter(codec: Codec, frames: list[list[Any]]) -> dict[str, tuple[float, list[float]]]:
    stamps: dict[str, list[float]] = defaultdict(list)
    for stamp, frame_id, hexdata in frames:
        key = periodic_key(codec, frame_id, bytes.fromhex(hexdata))
        if key is not None:
            stamps[key].append(stamp)
    return {key: (cycle, dev) for key, cycle, dev in deviations(codec, stamps)}


def _gap_note(r: dict[str, Any]) -> str:
    """The longest /odom gap, where it came from: the wheel frames' arrival (the emulator's send
    times; what the emulator process did meanwhile), the driver's handling (what it did
    between the two updates) and both processes' run-queue waits."""
    d = r["driver"]
    rx0, rx1 = d["odom_max_gap_rx"]
    run, wait, _ = r["emulator_in_gap"]
    drun, dwait, _ = r["driver_in_gap"]
    return (f"{d['odom_max_gap'] * 1e3:.1f} ms at {d['odom_max_gap_at']:.1f} s (its frames arrived "
            f"{(rx1 - rx0) * 1e3:.1f} ms apart, the emulator meanwhile ran {run * 1e3:.1f} / "
            f"waited runnable {wait * 1e3:.1f} ms; the driver between the two "
            f"updates ran {drun * 1e3:.1f} / waited {dwait * 1e3:.1f} ms; run-queue wait over "
            f"the run: emulator {r['wait_emulator']:.1f} s, driver {d['run_queue_wait']:.1f} s; "
            f"load {r['load']:.1f})")


def _summary(r: dict[str, Any], codec: Codec) -> dict[str, Any]:
    d, e = r["driver"], r["emulator"]
    upper_rx = (e.get("rx_frames", 0) - e.get("rx_unknown_id", 0) - e.get("rx_not_classic", 0)
                - e.get("rx_ignored", 0))
    by_counter, by_count, received = lost_from_lower(codec, r["frames"])
    return {"lost_up": by_counter, "lost_up_count": by_count, "received": received,
            "lost_down": d["sent"] - upper_rx, "sent_down": d["sent"],
            "odom_hz": d["odom"] / d["seconds"], "odom_gap": d["odom_max_gap"] * 1e3,
            "gap_note": _gap_note(r),
            "cpu_emu": r["cpu_emulator"] * 100, "cpu_drv": d["cpu"] / d["seconds"] * 100,
            "cpu_gen": r["cpu_foreign"] * 100, "foreign_seen": d["foreign"],
            "own_rate": (len(r["frames"]) + d["sent_in_window"]) / d["seconds"],
            "jitter": jitter(codec, r["frames"])}


def _pct(dev: list[float]) -> str:
    return f"{percentile(dev, 50):.2f}/{percentile(dev, 99):.2f}/{max(dev):.2f}"


def run(quick: bool = False) -> list[Row]:
    seconds = 5.0 if quick else 30.0
    codec = default_codec()
    capacity = BITRATE / mean_frame_bits(8, samples=5000 if quick else 20000)
    idle = _summary(trial(seconds, 0.0), codec)
    rate = max(capacity - idle["own_rate"], 0.0)
    raw = trial(seconds, rate)
    full = _summary(raw, codec)
    sent = raw["foreign"]["sent"] / raw["foreign"]["seconds"]
    g = "bus"
    rows = [
        Row(g, "foreign frames on the bus (full bus run)", sent, "frames/s",
            f"capacity {capacity:,.0f}/s (500 kbit/s, 8-byte frames, stuffed) minus own "
            f"{idle['own_rate']:.0f}/s; IDs off the catalog, 1/4 one bit from a catalog ID; "
            f"{full['foreign_seen']} reached the driver core; generator CPU "
            f"{full['cpu_gen']:.0f} %"),
        Row(g, "own frames lost, emulator -> driver, full bus", full["lost_up"], "frames",
            f"target 0; idle {idle['lost_up']}; rolling counters of {full['received']} "
            f"periodic frames in {seconds:g} s (cycles the emulator skipped, by the counts: "
            f"full {full['lost_up_count']}, idle {idle['lost_up_count']})"),
        Row(g, "own frames lost, driver -> emulator, full bus", full["lost_down"], "frames",
            f"target 0; idle {idle['lost_down']}; driver sent {full['sent_down']}, counted "
            "against the emulator's rx counters"),
        Row(g, "driver /odom rate, full bus", full["odom_hz"], "Hz",
            f"idle {idle['odom_hz']:.1f} Hz; longest gap full {full['gap_note']}, idle "
            f"{idle['gap_note']}"),
        Row(g, "CPU, emulator process, full bus", full["cpu_emu"], "% of a core",
            f"idle {idle['cpu_emu']:.1f} % (/proc/<pid>/stat utime+stime over the run)"),
        Row(g, "CPU, driver core process, full bus", full["cpu_drv"], "% of a core",
            f"idle {idle['cpu_drv']:.1f} %"),
    ]
    for key in sorted(full["jitter"]):
        cycle, dev = full["jitter"][key]
        quiet = idle["jitter"].get(key, (cycle, [float("nan")]))[1]
        rows.append(Row(g, f"{key} ({cycle * 1e3:g} ms) p99 jitter, full bus",
                        percentile(dev, 99), "ms",
                        f"p50/p99/max full {_pct(dev)} ms, idle {_pct(quiet)} ms"))
    return rows
