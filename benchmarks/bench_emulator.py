"""The emulated lower computer: simulated-clock speed, chassis per core, real-time jitter."""

from __future__ import annotations

import itertools
import subprocess
import sys
import time
from collections import defaultdict

from benchmarks import cli_runs
from benchmarks.common import Row, percentile
from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.clock import SimClock
from lowerbase.firmware_model.fastloop import LeanLoop
from lowerbase.firmware_model.mcu import Command, Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import bus_sender
from lowerbase.firmware_model.sim import SimRig
from lowerbase.protocol.codec import Codec, default_codec
from lowerbase.transport import free_loopback_port, open_bus

GROUP = "239.74.163.98"


def sim_speed(seconds: float, lean: bool = True, compiled: bool = True, scheduled: bool = True,
              repeat: int = 3) -> float:
    """Chassis seconds per CPU second (best of ``repeat``): one MCU with its BMS, driving,
    every frame encoded. The harness plays the upper computer: a MotionCommand encoded every
    20 ms with its rolling Counter; ``scheduled``: a second of them at a time handed to
    ``Mcu.advance(n, incoming)`` with their periods (runs of compiled periods span repeated
    commands), else ``SimRig.drive`` (each command received, then ``advance(4)``).
    ``lean=False`` checks the fault hooks in every period (Mcu.step); ``compiled=False``
    keeps the lean loop in Python (no numba kernel)."""
    best = 0.0
    for _ in range(repeat):
        p = load_profile()
        saved = LeanLoop.compiled
        LeanLoop.compiled = compiled
        try:
            rig = SimRig(p, bms=McuBmsAdapter.from_battery_table(p.battery), keep=False)
        finally:
            LeanLoop.compiled = saved
        rig.mcu.lean = lean
        rig.enable()
        t0 = time.process_time()
        if scheduled:
            _drive_scheduled(rig, 0.6, 0.2, seconds)
        else:
            rig.drive(0.6, 0.2, seconds)
        best = max(best, seconds / (time.process_time() - t0))
    return best


def _drive_scheduled(rig: SimRig, linear: float, angular: float, seconds: float) -> None:
    """What ``rig.drive(linear, angular, seconds)`` does, the commands handed to the Mcu a
    second at a time with the period each arrives before."""
    mcu, msg = rig.mcu, rig.codec.message("MotionCommand")
    every, block = round(0.02 / mcu.dt), round(1.0 / mcu.dt)
    total = round(seconds / mcu.dt)
    counter = 0
    for start in range(0, total, block):
        n = min(block, total - start)
        frames = []
        for k in range(0, n, every):
            frames.append((k, msg.frame_id, msg.encode(
                {"Linear": linear, "Angular": angular, "Mode": "Raw", "Counter": counter})))
            counter = (counter + 1) & 0xF
        mcu.advance(n, frames)


def chassis_per_core(seconds: float) -> tuple[float, float]:
    """(chassis one core can run in real time, frames/s each) with every frame sent to a real
    udp_multicast bus (hop limit 0) through the emulator's own send path
    (``runner.bus_sender``), measured on the simulated clock."""
    p = load_profile()
    bus = open_bus(interface="udp_multicast", channel=GROUP, port=free_loopback_port(), hop_limit=0)
    sent = 0
    to_bus = bus_sender(bus)

    def send(frame_id: int, data: bytes) -> None:
        nonlocal sent
        to_bus(frame_id, data)
        sent += 1

    clock = SimClock()
    mcu = Mcu(p, clock, send, bms=McuBmsAdapter.from_battery_table(p.battery))
    steps = round(seconds / mcu.dt)
    t0 = time.perf_counter()
    for k in range(steps):
        if k == 70:  # after the boot
            mcu.control(Command.ENABLE_CAN_CONTROL)
        if k % 4 == 0:
            mcu.command(0.6, 0.2)
        mcu.step()
        clock.advance(mcu.dt)
    wall = time.perf_counter() - t0
    bus.shutdown()
    assert mcu.stats["tx_errors"] == 0, "the bus refused frames"
    return seconds / wall, sent / seconds


def jitter(seconds: float) -> list[Row]:
    """Period jitter of each periodic frame of `lowerbase emulate` in real time."""
    port = free_loopback_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "lowerbase", "emulate", "-i", "udp_multicast", "-c", GROUP,
         "--bus-kwargs", f"port={port}", "hop_limit=0", "--duration", str(seconds + 3)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    proc.stdout.readline()  # "lower computer on ..."
    bus = open_bus(interface="udp_multicast", channel=GROUP, port=port, hop_limit=0)
    codec = default_codec()
    stamps: dict[str, list[float]] = defaultdict(list)
    end = time.monotonic() + seconds + 1.0
    start = time.monotonic() + 1.0  # skip the boot
    while time.monotonic() < end:
        msg = bus.recv(0.5)
        if msg is None or time.monotonic() < start:
            continue
        key = periodic_key(codec, msg.arbitration_id, bytes(msg.data))
        if key is not None:
            stamps[key].append(msg.timestamp)
    bus.shutdown()
    proc.wait(timeout=10)
    rows = []
    for key, cycle, dev in deviations(codec, stamps):
        rows.append(Row("jitter", f"{key} ({cycle * 1e3:g} ms) p50/p99/max",
                        percentile(dev, 50), "ms",
                        f"p99 {percentile(dev, 99):.2f} ms, max {max(dev):.2f} ms, "
                        f"{len(stamps[key])} frames"))
    return rows


def periodic_key(codec: Codec, frame_id: int, data: bytes) -> str | None:
    """The stream a periodic frame of the lower computer belongs to (``WheelFeedback/left``,
    ``LedState/02``, ``Heartbeat``), or None for any other frame."""
    if frame_id not in codec:
        return None
    m = codec.message(frame_id)
    if not m.is_periodic or "Lower" not in m.senders:
        return None
    if m.name == "WheelFeedback":
        return m.name + "/" + ("left" if data[7] & 1 == 0 else "right")
    if m.name == "LedState":
        return m.name + f"/{data[0]:02x}"
    return m.name


def deviations(codec: Codec, stamps: dict[str, list[float]]
               ) -> list[tuple[str, float, list[float]]]:
    """(stream, cycle [s], |period - cycle| [ms] of each pair of consecutive frames) for
    each stream of :func:`periodic_key` (one LedState submodule stands for the 16)."""
    out = []
    for key in sorted(stamps):
        name = key.split("/")[0]
        if name == "LedState" and not key.endswith("/02"):
            continue
        cycle = codec.message(name).cycle_time or 0.0
        dev = [abs((b - a) - cycle) * 1e3 for a, b in itertools.pairwise(stamps[key])]
        if dev:
            out.append((key, cycle, dev))
    return out


def run(quick: bool = False) -> list[Row]:
    speed = sim_speed(20.0 if quick else 120.0)
    per_call = sim_speed(20.0 if quick else 120.0, scheduled=False)
    python = sim_speed(20.0 if quick else 120.0, compiled=False, repeat=1)
    hooked = sim_speed(20.0 if quick else 120.0, lean=False, repeat=1)
    per_core, fps = chassis_per_core(10.0 if quick else 60.0)
    rows = [
        Row("emulator", "simulated clock, one chassis", speed, "x real time",
            "target >= 1000x; by CPU, best of 3; MCU + BMS at 200 Hz, all frames encoded, no "
            "bus, a MotionCommand encoded every 20 ms and handed to Mcu.advance with its "
            "period a second ahead; the lean period compiled (numba; about 8 s CPU to compile "
            "once, then cached)"),
        Row("emulator", "simulated clock, one chassis, a command per advance call", per_call,
            "x real time", "the same driven by SimRig.drive (receive, then advance(4): a "
            "compiled run per command)"),
        Row("emulator", "simulated clock, one chassis, Python lean loop", python, "x real time",
            "the same without the compiled period (no numba; docs/emulator.md)"),
        Row("emulator", "simulated clock, one chassis, fault hooks in every period", hooked,
            "x real time", "the same with the fault hooks checked in every period, in Python "
            "(what the periods with a fault acting cost; docs/emulator.md)"),
        Row("emulator", "chassis per core in real time", per_core, "chassis",
            f"target >= 300; all frames ({fps:.0f}/s each) sent on udp_multicast; one "
            "chassis alone (bench_fleet: a fleet of N)"),
    ]
    return rows + cli_rows(60.0 if quick else 600.0) + jitter(5.0 if quick else 30.0)


def cli_rows(seconds: float) -> list[Row]:
    """``lowerbase emulate --simulated`` as users run it, in a child process, by its CPU time
    (issue 22 item 25): on udp_multicast (the default bus) and on python-can's virtual bus."""
    rows = []
    for label, bus in (("udp_multicast", ()), ("-i virtual", ("-i", "virtual"))):
        run = cli_runs.emulate(seconds, bus)
        rows += [
            Row("emulator", f"CLI emulate --simulated, {label}", run.factor, "x real time",
                f"`python -m lowerbase emulate {' '.join(bus)} --simulated --duration "
                f"{seconds:g}` in a child process, by its CPU time, start-up subtracted; no "
                "upper side on the bus, so the MCU idles (no MotionCommand) and steps period "
                "by period (fastbatch runs need a command)"),
            Row("emulator", f"CLI emulate --simulated, {label}, start-up", run.startup_cpu,
                "s CPU", "the same command with --duration 0.01: imports, the cached kernels, "
                "the bus"),
        ]
    return rows
