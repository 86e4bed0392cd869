"""Processes for the full-bus benchmark (benchmarks/bench_bus.py), each on a udp_multicast bus.

``python -m benchmarks.busload_proc driver --port P --duration S --frames FILE``: the
driver core (:class:`~lowerbase.driver.core.DriverCore`) in real time against a lower computer
on the bus, listening as the ROS node's :class:`~lowerbase.driver.links.BusLink` does
(``--no-filter``: to everything), each frame stamped at its kernel receive time as the
node stamps it. It drives a twist, waits until the link is ``ready``, prints
``measuring`` and for ``S`` seconds records every frame from the lower computer (kernel receive
time, ID, data) into FILE as JSON; then it prints one JSON line of stats: what it sent since it
started (for a count comparison with the lower computer's ``rx_frames``), odometry updates
(the ROS node publishes /odom on each) and their longest gap (when in the window, and the
kernel receive times of the two wheel frames behind it: a gap already there when the frames
arrived was the sender's; and the wall times they were handled at), its CPU time and
run-queue wait over the window (``/proc/self``).

``python -m benchmarks.busload_proc foreign --port P --rate R --duration S``: another
device filling the bus: ``R`` classic 8-byte frames a second, paced, on IDs the catalog does
not have (a quarter of them one bit away from a catalog ID, the rest anywhere in the 11-bit
range), random data, seeded; on SIGTERM or after ``S`` s it prints one JSON line (frames sent,
seconds). Both bind and send on loopback only (hop limit 0).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import sys
import threading
import time
from typing import Any, TypeVar

from lowerbase.transport import DEFAULT_CHANNEL, open_bus

T = TypeVar("T")

DT = 0.005  #: [s] the driver core's tick (as the demo's BusHarness)
TWIST = (0.4, 0.3)  #: [m/s, rad/s] driven for the whole run
TWIST_PERIOD = 0.05  #: [s] how often a twist arrives (a 20 Hz /base_cmd_vel)
READY_TIMEOUT = 20.0  #: [s] for the link to become ready


def cpu_seconds(pid: int | str = "self") -> float:
    """utime + stime of a process [s], from /proc/<pid>/stat."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_queue_wait(pid: int | str = "self") -> float:
    """Time a process' threads waited runnable on a run queue [s] (/proc/<pid>/schedstat)."""
    with open(f"/proc/{pid}/schedstat", encoding="ascii") as f:
        return int(f.read().split()[1]) / 1e9


def bus_config(port: int, channel: str = DEFAULT_CHANNEL) -> dict[str, Any]:
    return {"interface": "udp_multicast", "channel": channel, "port": port, "hop_limit": 0}


def run_driver(port: int, duration: float, frames_path: str, *, channel: str = DEFAULT_CHANNEL,
               catalog_filter: bool = True) -> dict[str, Any]:
    import can

    from lowerbase.clock import RealClock
    from lowerbase.driver.core import DriverCore, LinkState
    from lowerbase.driver.links import listen_to_lower
    from lowerbase.transport import is_catalog_frame

    bus = open_bus(bus_config(port, channel))
    if catalog_filter:
        listen_to_lower(bus)
    sent = [0]

    def send(frame_id: int, data: bytes) -> None:
        try:
            bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
        except can.CanError:
            return
        sent[0] += 1

    clock = RealClock()
    core = DriverCore(send, clock)
    odom: list[float] = []
    rx_stamp = [0.0]  # kernel receive time of the frame being handled
    odom_rx: list[tuple[float, float]] = []  # (the frame's receive time, handled), wall clock

    def on_event(what: str, _core: Any) -> None:
        if what == "odometry":
            odom.append(clock.now())
            odom_rx.append((rx_stamp[0], time.time()))

    core.listeners.append(on_event)
    lower = {m.frame_id for m in core.codec if "Lower" in m.senders}
    frames: list[tuple[float, int, str]] = []
    foreign = 0
    recording = False
    start = clock.now()
    window: tuple[float, float] | None = None
    cpu0, sent0, wait0 = 0.0, 0, 0.0
    deadline = next_twist = start
    try:
        while True:
            now = clock.now()
            if window is None:
                if core.state == LinkState.READY and odom:
                    window = (now, now + duration)
                    recording, cpu0, sent0 = True, cpu_seconds(), sent[0]
                    wait0 = run_queue_wait()
                    odom.clear()
                    odom_rx.clear()
                    print("measuring", flush=True)
                elif now - start > READY_TIMEOUT:
                    raise SystemExit(f"the driver core did not get ready ({core.state.value})")
            elif now >= window[1]:
                break
            if now >= next_twist:
                core.set_twist(*TWIST)
                next_twist += TWIST_PERIOD
            deadline += DT
            while True:
                remaining = deadline - clock.now()
                msg = bus.recv(remaining if remaining > 0 else 0.0)
                if msg is None:
                    break
                if not is_catalog_frame(msg) or msg.arbitration_id not in core.codec:
                    foreign += 1
                    continue
                if recording and msg.arbitration_id in lower:
                    frames.append((msg.timestamp, msg.arbitration_id, bytes(msg.data).hex()))
                rx_stamp[0] = msg.timestamp
                handle_frame(core, msg, time.time())
            core.heard_until = clock.now()  # listened until now and found the socket empty
            if clock.now() - deadline > 1.0:
                deadline = clock.now()
            core.tick()
        cpu = cpu_seconds() - cpu0
        wait = run_queue_wait() - wait0
    finally:
        bus.shutdown()
    with open(frames_path, "w", encoding="utf-8") as f:
        json.dump(frames, f)
    assert window is not None
    gap, at, rx = longest_gap(odom, odom_rx)
    return {"sent": sent[0], "sent_in_window": sent[0] - sent0, "seconds": duration,
            "cpu": cpu, "run_queue_wait": wait, "odom": len(odom), "odom_max_gap": gap,
            "odom_max_gap_at": at - window[0], "odom_max_gap_rx": [rx[0][0], rx[1][0]],
            "odom_max_gap_wall": [rx[0][1], rx[1][1]],
            "foreign": foreign, "frames": len(frames), "malformed": core.stats["malformed"],
            "state": core.state.value}


def handle_frame(core: Any, msg: Any, wall_now: float) -> None:
    """Hand ``msg`` to the driver core as the ROS node does: stamped at its kernel receive time
    (:func:`~lowerbase.driver.links.receive_age` at ``wall_now``), so that a backlog handled at
    once after the process waited is judged on the frames' spacing, not the burst's."""
    from lowerbase.driver.links import receive_age

    stamp = core.clock.now() - receive_age(msg, wall_now)
    core.heard_until = stamp
    core.on_frame(msg.arbitration_id, bytes(msg.data), stamp)


def longest_gap(times: list[float], stamps: list[T]) -> tuple[float, float, tuple[T, T]]:
    """(the longest gap between consecutive ``times``, the time it starts at, the ``stamps`` of
    its two ends); NaNs for fewer than two times. ``stamps[i]`` goes with ``times[i]`` (here:
    the kernel receive time of the frame that made update ``i``)."""
    nan: Any = float("nan")
    best: tuple[float, float, tuple[T, T]] = (nan, nan, (nan, nan))
    for i in range(1, len(times)):
        gap = times[i] - times[i - 1]
        if not gap <= best[0]:  # also replaces the NaN start
            best = (gap, times[i - 1], (stamps[i - 1], stamps[i]))
    return best


def foreign_ids(codec: Any) -> tuple[list[int], list[int]]:
    """(IDs one bit away from a catalog ID, every other ID): none of them in the catalog."""
    catalog = {m.frame_id for m in codec}
    near = sorted({i ^ (1 << b) for i in catalog for b in range(11)} - catalog)
    far = sorted(set(range(0x800)) - catalog - set(near))
    return near, far


def run_foreign(port: int, rate: float, duration: float, *, channel: str = DEFAULT_CHANNEL,
                seed: int = 7) -> dict[str, Any]:
    from lowerbase.protocol.codec import default_codec

    near, far = foreign_ids(default_codec())
    rng = random.Random(seed)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    bus = open_bus(bus_config(port, channel))
    send_frame = bus.send_frame  # type: ignore[attr-defined]  # GroupOnlyMulticastBus
    sent = errors = 0
    start = time.monotonic()
    try:
        while not stop.is_set():
            now = time.monotonic()
            if now - start >= duration:
                break
            due = int(rate * (now - start)) - sent - errors
            for _ in range(max(due, 0)):
                frame_id = rng.choice(near) if rng.random() < 0.25 else rng.choice(far)
                try:
                    send_frame(frame_id, rng.randbytes(8))
                    sent += 1
                except Exception:  # a full socket buffer: counted, the pace goes on
                    errors += 1
            time.sleep(0.001)
    finally:
        bus.shutdown()
    return {"sent": sent, "errors": errors, "seconds": time.monotonic() - start}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.busload_proc")
    sub = parser.add_subparsers(dest="role", required=True)
    drv = sub.add_parser("driver")
    drv.add_argument("--frames", required=True)
    drv.add_argument("--no-filter", action="store_true")
    gen = sub.add_parser("foreign")
    gen.add_argument("--rate", type=float, required=True)
    for p in (drv, gen):
        p.add_argument("--port", type=int, required=True)
        p.add_argument("--channel", default=DEFAULT_CHANNEL)
        p.add_argument("--duration", type=float, required=True)
    args = parser.parse_args(argv)
    if args.role == "driver":
        out = run_driver(args.port, args.duration, args.frames, channel=args.channel,
                         catalog_filter=not args.no_filter)
    else:
        out = run_foreign(args.port, args.rate, args.duration, channel=args.channel)
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
