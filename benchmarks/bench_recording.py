"""MCAP recording benchmarks: the cost of writing a run as MCAP, per simulated second.

The demo scenario (scenarios/demo.toml) runs on the simulated clock three ways: without any
recorder, with the MCAP recorder's driver topics and frames (``McapRecorder``: /odom,
/odom_raw, /tf, /imu/data_raw, battery, BMS, status, truth, /can/frames) and with the decoded
JSON signals on top (what ``lowerbase scenario run`` writes by default). Rows: the extra wall
time per simulated second for each, and the file size per simulated second. Best of a few
repeats, measured back to back. The high-rate messages (frames, IMU, odometry, tf, status) are
packed by ``lowerbase.recording.fastser``: that took the default recording's extra from about
26 to about 15 ms CPU per simulated second (back to back, loaded 2-core machine); most of the
rest is the mcap writer's per-message Python and the decoded signals' JSON.

The live view (``--foxglove``): the same messages served by the Foxglove WebSocket server
(``lowerbase.recording.live.FoxgloveSink``) at the full frame rate of a drive on the simulated
clock (SimLoop: every emulator and driver frame, the driver topics, the truth). Rows: this
process's CPU time per simulated second without a publisher, with the live server and no
client (nothing is built: no channel is subscribed), and with a client (a child process on
loopback speaking the WebSocket protocol) subscribed to every channel.

A world run (the library's warehouse_localization, its first WORLD_SIM s: the lane drive
with amcl): CPU per simulated second without a recorder and the extra of the default MCAP
with the world's channels (/map, /scan at 25 Hz, /amcl_pose, map -> odom, the truth on the
map). Most of that extra is ray casting: the world casts only the scans amcl uses, the
recorder casts every other tick itself (lowerbase.recording.world).

``python -m benchmarks.bench_recording [--quick]`` prints the rows.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.common import Row


def _run(decoded: bool | None, path: Path) -> tuple[float, float]:
    """(wall s, simulated s) of the demo scenario; decoded None: no recorder."""
    from lowerbase.recording.mcap_writer import McapRecorder
    from lowerbase.scenarios.catalog import library
    from lowerbase.scenarios.runner import SimHarness, run_scenario
    from lowerbase.scenarios.wheeled import load_scenario

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
    return [*_mcap_rows(best, base, size, sim), *_world_rows(repeat), *_live_rows(repeat)]


WORLD_SIM = 10.0  #: simulated s of warehouse_localization


def _world(path: Path | None) -> tuple[float, int]:
    """(CPU s, scans the recorder cast) of WORLD_SIM s of warehouse_localization, recorded to
    ``path`` with the world's channels (None: no recorder)."""
    import dataclasses

    from lowerbase.recording.mcap_writer import McapRecorder
    from lowerbase.recording.world import attach_world
    from lowerbase.scenarios.catalog import library
    from lowerbase.scenarios.runner import SimHarness, run_scenario
    from lowerbase.scenarios.wheeled import load_scenario

    sc = dataclasses.replace(load_scenario(library()["warehouse_localization"]),
                             duration=WORLD_SIM, expectations=())
    t0 = time.process_time()
    rec = McapRecorder(path) if path is not None else None
    harness = SimHarness(sc, tap=rec)
    feed = None
    if rec is not None:
        rec.attach(harness.driver, harness.now, harness.truth)
        feed = attach_world(rec, harness.world)
    try:
        run_scenario(sc, harness)
    finally:
        harness.close()
        if rec is not None:
            rec.close()
    return time.process_time() - t0, feed.own_scans if feed is not None else 0


def _world_rows(repeat: int) -> list[Row]:
    best: dict[str, float] = {}
    size = own = 0
    with tempfile.TemporaryDirectory(prefix="bench-recording-world-") as tmp:
        path = Path(tmp) / "world.mcap"
        for _ in range(repeat):
            for key, where in (("none", None), ("mcap", path)):
                cpu, n = _world(where)
                best[key] = min(best.get(key, float("inf")), cpu)
                if where is not None:
                    size, own = path.stat().st_size, n
    base = best["none"] / WORLD_SIM
    return [
        Row("recording", "world run (warehouse_localization), no recorder", 1e3 * base,
            "ms CPU per sim s", f"{WORLD_SIM:g} s simulated, amcl"),
        Row("recording", "MCAP of a world run (default + /map /scan /amcl_pose ...)",
            1e3 * (best["mcap"] / WORLD_SIM - base), "ms CPU per sim s",
            f"extra; {own / WORLD_SIM:.0f} scans per sim s cast by the recorder"),
        Row("recording", "MCAP file size of a world run", size / WORLD_SIM / 1e3,
            "kB per sim s", "zstd chunks; /map once"),
    ]


def _mcap_rows(best: dict[str, float], base: float, size: int, sim: float) -> list[Row]:
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


LIVE_WARMUP = 2.0  #: simulated s before the measurement: every channel is open by then
LIVE_DRIVE = 20.0  #: simulated s measured


def _live(variant: str) -> tuple[float, int, int]:
    """(CPU s of this process, messages sent, messages the client got) over LIVE_DRIVE
    simulated s (a client that lags loses the oldest: the server's per-client backlog).
    variant: "none" (no publisher), "idle" (live server, no client), "client"."""
    from lowerbase.recording.live import FoxgloveSink
    from lowerbase.recording.publisher import RunPublisher
    from lowerbase.simloop.loop import SimLoop

    sink = FoxgloveSink("127.0.0.1", 0) if variant != "none" else None
    pub = RunPublisher([sink]) if sink is not None else None
    loop = SimLoop(tap=pub)
    tr = loop.mcu.truth
    if pub is not None:
        pub.attach(loop.driver, loop.clock.now, lambda: (tr.x, tr.y, tr.yaw, tr.v, tr.w))
    loop.run(LIVE_WARMUP)
    client: Any = None
    if variant == "client" and sink is not None:
        client = subprocess.Popen([sys.executable, "-m", "benchmarks.bench_recording",
                                   "--client", sink.url], stdout=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 30
        while not all(sink.subscribed(t) for t in sink.topics):
            if time.monotonic() > deadline or client.poll() is not None:
                raise RuntimeError("the benchmark's WebSocket client did not subscribe")
            time.sleep(0.01)
    before = sum(pub.counts.values()) if pub is not None else 0
    t0 = time.process_time()
    loop.drive(0.5, 0.3, LIVE_DRIVE)
    cpu = time.process_time() - t0
    sent = sum(pub.counts.values()) - before if pub is not None else 0
    got = 0
    if pub is not None:
        pub.close()  # stops the server: the client's connection ends
    if client is not None:
        out, _ = client.communicate(timeout=60)
        got = int(out.strip() or 0)
    return cpu, sent, got


def _live_rows(repeat: int) -> list[Row]:
    best: dict[str, float] = {}
    sent = got = 0
    for _ in range(repeat):
        for key in ("none", "idle", "client"):
            cpu, n_sent, n_got = _live(key)
            best[key] = min(best.get(key, float("inf")), cpu)
            if key == "client":
                sent, got = max(sent, n_sent), max(got, n_got)
    base = best["none"] / LIVE_DRIVE
    return [
        Row("recording", "live view: drive at full frame rate, no publisher", 1e3 * base,
            "ms CPU per sim s", f"{LIVE_DRIVE:g} s simulated (SimLoop)"),
        Row("recording", "live view: Foxglove server, no client", 1e3 * (
            best["idle"] / LIVE_DRIVE - base), "ms CPU per sim s", "extra; nothing built"),
        Row("recording", "live view: Foxglove server, client on every channel", 1e3 * (
            best["client"] / LIVE_DRIVE - base), "ms CPU per sim s",
            f"extra; {sent / LIVE_DRIVE:.0f} messages per sim s, "
            f"{got / LIVE_DRIVE:.0f} delivered (as fast as the simulation runs)"),
    ]


def _client(url: str) -> None:
    """Subscribe to every channel advertised; print the number of messages received once the
    server closes the connection."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    n = 0
    with connect(url, subprotocols=["foxglove.sdk.v1"]) as ws:  # type: ignore[list-item]
        subs = 0
        try:
            for raw in ws:
                if isinstance(raw, bytes):
                    n += 1
                    continue
                msg = json.loads(raw)
                if msg["op"] == "advertise":
                    new = [{"id": subs + i + 1, "channelId": ch["id"]}
                           for i, ch in enumerate(msg["channels"])]
                    subs += len(new)
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
        except ConnectionClosed:
            pass
    print(n)


if __name__ == "__main__":
    if "--client" in sys.argv:
        _client(sys.argv[sys.argv.index("--client") + 1])
        sys.exit(0)
    from benchmarks.__main__ import table

    print(table(run(quick="--quick" in sys.argv)))
