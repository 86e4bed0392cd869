"""The legged robot: 12 actuators at 1 kHz on four buses in real time, and the simulated clock.

Real time: ``lowerbase emulate --robot legged`` in its own process on udp_multicast (loopback,
one group, ports PORT..PORT+3 of its own: bus k = FR, FL, RR, RL on PORT+k, as the conformance
BusesLink and the legged driver open them). A client in this process brings the robot to
IN_TEST_MODE (where the body controller falls silent and each actuator answers the upper
side's command at once) and commands all 12 actuators every 1 ms: 3 commands and 3 replies per
ms per leg bus, the issue's 6,000 frames/s per bus. Per bus: commands sent against replies
received (and the emulator's own rx count: lost on the way down vs. up), the reply period's
deviation from 1 ms (kernel receive timestamps, per actuator), the round trip command ->
reply, and the CPU of both processes (``/proc/<pid>/stat`` utime+stime over the window).

Simulated clock: the lower computer alone (LeggedLower on a SimClock, every frame encoded,
nothing listening) and with the legged driver core and the node's goal logic
(``lowerbase.simloop.legged.LeggedSimLoop``: every frame decoded by the driver), both
trotting under a velocity command, in robot seconds per wall second.
"""

from __future__ import annotations

import itertools
import math
import os
import selectors
import socket
import subprocess
import time
from collections.abc import Callable
from typing import Any

import can

from benchmarks.bench_bus import _emulator_stats, _line, _proc, _stop
from benchmarks.busload_proc import cpu_seconds
from benchmarks.common import Row, percentile
from lowerbase.clock import SimClock
from lowerbase.firmware_model.runner import FULL_ID_MASK
from lowerbase.protocol.codec import Codec
from lowerbase.protocol.legged import (
    BODY_BUS,
    COMMAND_MESSAGES,
    LEGS,
    N_BUSES,
    REPLY_ID,
    LocomotionState,
    legged_codec,
)
from lowerbase.transport import open_bus

S = LocomotionState
GROUP = "239.74.163.15"
PERIOD = 0.001  #: [s] the commands' DBC cycle
START_TIMEOUT = 30.0
#: the way to IN_TEST_MODE along the state table (MOTOR_ENABLED through MOTOR_COMMUTATION)
BRING_UP = (S.COMM_ENABLED, S.MOTOR_READY, S.MOTOR_ENABLED, S.IN_TEST_MODE)
MOTORS = tuple(COMMAND_MESSAGES)  #: CAN IDs 1..3 on each leg bus


def free_port_range(n: int = N_BUSES) -> int:
    """A port P with P..P+n-1 free for UDP (nothing bound to them on any address)."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
        if port + n > 65535:
            continue
        socks = []
        try:
            for p in range(port, port + n):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("0.0.0.0", p))
            return port
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError(f"no {n} consecutive free UDP ports")


class Client:
    """The upper side on the four leg buses: commands, replies, LocomotionStatus."""

    def __init__(self, port: int, codec: Codec) -> None:
        self.codec = codec
        self.status_id = codec.message("LocomotionStatus").frame_id
        self.buses: list[can.BusABC] = []
        self.selector = selectors.DefaultSelector()
        for k in range(N_BUSES):
            bus = open_bus({"interface": "udp_multicast", "channel": GROUP, "port": port + k,
                            "hop_limit": 0})
            self.buses.append(bus)
            ids = [REPLY_ID, self.status_id] if k == BODY_BUS else [REPLY_ID]
            bus.set_filters([{"can_id": i, "can_mask": FULL_ID_MASK} for i in ids])
            self.selector.register(bus.fileno(), selectors.EVENT_READ, k)
        self.send_frame: list[Callable[[int, bytes], None]] = [b.send_frame  # type: ignore
                                                               for b in self.buses]
        self.state: int | None = None
        self.recording = False
        #: kernel receive stamps of the replies, [bus][motor id]
        self.replies: list[dict[int, list[float]]] = [{m: [] for m in MOTORS}
                                                      for _ in range(N_BUSES)]
        self.extra_replies = 0  #: replies without a motor id of ours
        self.sent_frames = 0  #: every frame this client sent (the emulator's rx_frames)

    def drain(self, k: int) -> None:
        bus = self.buses[k]
        while (msg := bus.recv(0.0)) is not None:
            if msg.arbitration_id == REPLY_ID:
                if self.recording:
                    stamps = self.replies[k].get(msg.data[0])
                    if stamps is None:
                        self.extra_replies += 1
                    else:
                        stamps.append(msg.timestamp)
            elif msg.arbitration_id == self.status_id:
                self.state = int(self.codec.decode(self.status_id, bytes(msg.data))[1]["State"])

    def pump(self, until: float) -> None:
        """Receive on every bus until ``time.monotonic()`` reaches ``until``."""
        while (remaining := until - time.monotonic()) > 0:
            for key, _ in self.selector.select(remaining):
                self.drain(key.data)
        for k in range(N_BUSES):
            self.drain(k)

    def request(self, target: S, counter: int, timeout: float = 5.0) -> None:
        data = self.codec.encode("LocomotionRequest", {"Request": int(target),
                                                       "Counter": counter % 16})
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.send_frame[BODY_BUS](self.codec.message("LocomotionRequest").frame_id, data)
            self.sent_frames += 1
            self.pump(time.monotonic() + 0.1)
            if self.state == target:
                return
        raise RuntimeError(f"the emulator did not reach {target.name} (state {self.state})")

    def command_loop(self, seconds: float) -> dict[str, Any]:
        """Every 1 ms: one MIT command to each of the 12 actuators (a slow sine about 0 rad,
        kp 20, kd 0.5), then the replies that arrived (their kernel stamps tell when), then
        sleep until the next deadline. Deadlines advance by exactly 1 ms (a late cycle is caught
        up at once, as the emulator's runner does; more than 1 s late: skipped)."""
        messages = {m: self.codec.message(COMMAND_MESSAGES[m]) for m in MOTORS}
        sent: list[dict[int, list[float]]] = [{m: [] for m in MOTORS} for _ in range(N_BUSES)]
        self.recording = True
        cpu0, wall0 = time.process_time(), time.monotonic()
        deadline, cycle, n = wall0, 0, round(seconds / PERIOD)
        while cycle < n:
            p = 0.3 * math.sin(2 * math.pi * cycle * PERIOD)
            for m in MOTORS:
                data = messages[m].encode({"Position": p, "Velocity": 0.0, "Kp": 20.0,
                                           "Kd": 0.5, "Torque": 0.0})
                for k in range(N_BUSES):
                    sent[k][m].append(time.time())
                    self.send_frame[k](m, data)
            cycle += 1
            deadline += PERIOD
            for k in range(N_BUSES):
                self.drain(k)
            now = time.monotonic()
            if now < deadline:  # not selector.select: epoll's timeout rounds up to 1 ms
                time.sleep(deadline - now)
            elif now - deadline > 1.0:
                deadline = now
        wall = time.monotonic() - wall0
        cpu = time.process_time() - cpu0
        self.sent_frames += n * len(MOTORS) * N_BUSES
        return {"sent": sent, "wall": wall, "cpu": cpu, "cycles": n,
                "send_dev": _period_dev(sent[BODY_BUS][MOTORS[0]])}

    def close(self) -> None:
        self.selector.close()
        for bus in self.buses:
            bus.shutdown()


def _period_dev(stamps: list[float]) -> list[float]:
    """abs(interval - 1 ms) [ms] of consecutive ``stamps`` [s]."""
    return [abs(b - a - PERIOD) * 1e3 for a, b in itertools.pairwise(stamps)]


def _bus_summary(sent: dict[int, list[float]], got: dict[int, list[float]],
                 wall: float) -> dict[str, Any]:
    n_sent = sum(len(v) for v in sent.values())
    n_got = sum(len(v) for v in got.values())
    period_dev: list[float] = []
    rtt: list[float] = []
    unmatched = 0
    for m in MOTORS:
        stamps = got[m]
        period_dev += _period_dev(stamps)
        if len(stamps) == len(sent[m]):  # nothing lost: the n-th reply answers the n-th command
            rtt += [(r - s) * 1e3 for s, r in zip(sent[m], stamps, strict=True)]
        else:
            unmatched += 1
    return {"sent": n_sent, "got": n_got, "lost": n_sent - n_got,
            "rate": (n_sent + n_got) / wall, "dev": period_dev, "rtt": rtt,
            "unmatched": unmatched}


def realtime_trial(seconds: float) -> dict[str, Any]:
    """One run of the emulator process and the client (see the module)."""
    codec = legged_codec()
    port = free_port_range()
    bound = str(seconds + START_TIMEOUT + 20)  # the emulator ends by itself
    emu = _proc("lowerbase", "emulate", "--robot", "legged", "-i", "udp_multicast", "-c", GROUP,
                "--bus-kwargs", f"port={port}", "hop_limit=0", "--duration", bound,
                stderr=subprocess.PIPE)
    client = None
    try:
        _line(emu, "legged lower computer on")
        client = Client(port, codec)
        client.pump(time.monotonic() + 0.2)
        for i, target in enumerate(BRING_UP):
            client.request(target, i)
        client.pump(time.monotonic() + 0.1)  # the body controller's last frames
        emu_cpu0 = cpu_seconds(emu.pid)
        loop = client.command_loop(seconds)
        emu_cpu = cpu_seconds(emu.pid) - emu_cpu0
        client.pump(time.monotonic() + 0.3)  # replies still on their way
        load = os.getloadavg()[0]
        stats = _emulator_stats(_stop(emu)[1])
    finally:
        if client is not None:
            client.close()
        if emu.poll() is None:
            emu.kill()
            emu.wait()
    buses = [_bus_summary(loop["sent"][k], client.replies[k], loop["wall"])
             for k in range(N_BUSES)]
    return {"buses": buses, "wall": loop["wall"], "cycles": loop["cycles"],
            "send_dev": loop["send_dev"],
            "cpu_client": loop["cpu"] / loop["wall"] * 100,
            "cpu_emulator": emu_cpu / loop["wall"] * 100, "load": load,
            "lost_down": client.sent_frames - stats.get("rx_frames", 0),
            "refused": stats.get("rx_actuator_command_refused", 0),
            "extra": client.extra_replies}


def _pct(dev: list[float]) -> str:
    return (f"{percentile(dev, 50):.2f}/{percentile(dev, 99):.2f}/"
            f"{max(dev, default=math.nan):.2f}")


def realtime_rows(seconds: float) -> list[Row]:
    r = realtime_trial(seconds)
    g, buses = "legged", r["buses"]
    sent = sum(b["sent"] for b in buses)
    cond = (f"{seconds:g} s, {r['cycles'] / r['wall']:.0f} command cycles/s, load avg "
            f"{r['load']:.1f} on {os.cpu_count()} cores")
    rates = [b["rate"] for b in buses]
    rows = [
        Row(g, "replies lost, 12 actuators at 1 kHz, real time",
            sum(b["lost"] for b in buses), "frames",
            f"target 0; of {sent} commands (per bus {'/'.join(str(b['lost']) for b in buses)}"
            f"); {r['lost_down']} never reached the emulator, {r['refused']} refused, "
            f"{r['extra']} replies from other motor IDs; {cond}"),
        Row(g, "frames/s per leg bus, commands + replies (slowest bus)", min(rates),
            "frames/s", "target 6,000; " + ", ".join(f"{LEGS[k]} {v:,.0f}"
                                                      for k, v in enumerate(rates))),
        Row(g, "command period jitter p99 (the client)", percentile(r["send_dev"], 99), "ms",
            f"deviation from 1 ms p50/p99/max {_pct(r['send_dev'])} ms: this process's own "
            "timing (time.sleep to each deadline, late cycles caught up)"),
    ]
    for k, b in enumerate(buses):
        rtt = f"round trip p50/p99/max {_pct(b['rtt'])} ms" if b["rtt"] else \
            "round trip n/a (replies lost)"
        rows.append(Row(g, f"bus {k} ({LEGS[k]}): reply period jitter p99",
                        percentile(b["dev"], 99), "ms",
                        f"deviation from 1 ms p50/p99/max {_pct(b['dev'])} ms, per actuator, "
                        f"kernel receive stamps; {rtt} (send -> kernel stamp)"))
    rows += [
        Row(g, "CPU, emulator process (12 actuators at 1 kHz)", r["cpu_emulator"],
            "% of a core", "/proc/<pid>/stat utime+stime over the window; IN_TEST_MODE: every "
            "command decoded, every reply encoded, the 1 kHz models, body frames"),
        Row(g, "CPU, client (this process)", r["cpu_client"], "% of a core",
            "encodes 12 commands per ms, receives 12 replies per ms (python-can recv)"),
    ]
    return rows


# -- the simulated clock ----------------------------------------------------------------------


def _lower_alone(seconds: float) -> tuple[float, float, int]:
    """(wall s, CPU s, frames) for ``seconds`` of the lower computer trotting on a SimClock."""
    from lowerbase.legged.lower import LeggedLower
    from lowerbase.legged.profile import LeggedProfile
    from lowerbase.legged.runner import legged_bms

    profile = LeggedProfile()
    clock = SimClock()
    frames = [0]

    def send(bus: int, frame_id: int, data: bytes) -> None:
        frames[0] += 1

    lower = LeggedLower(profile, clock, send, bms=legged_bms(profile))

    def step() -> None:
        lower.step()
        clock.advance(lower.dt)

    for target in (S.COMM_ENABLED, S.MOTOR_READY, S.MOTOR_ENABLED, S.STANDING_MODE,
                   S.IN_CONTROL):
        for i in range(5000):  # requested again every 50 ms while Busy
            if lower.body.state is target:
                break
            if i % 50 == 0:
                lower.request(int(target))
            step()
        if lower.body.state != target:
            raise RuntimeError(f"the lower computer did not reach {target.name}")
    frames[0] = 0
    n, every = round(seconds / lower.dt), round(0.02 / lower.dt)
    t0, cpu0 = time.perf_counter(), time.process_time()
    for i in range(n):
        if i % every == 0:
            lower.body.velocity_command(0.5, 0.0, 0.2)
        step()
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    if lower.body.state != S.IN_CONTROL:
        raise RuntimeError(f"stopped trotting: {lower.body.state.name}")
    lower.shutdown()
    return wall, cpu, frames[0]


def _with_driver(seconds: float) -> tuple[float, float, int]:
    """(wall s, CPU s, frames) for ``seconds`` of LeggedSimLoop (lower computer + driver core
    + goal logic) trotting under a 20 Hz cmd_vel."""
    from lowerbase.simloop.legged import LeggedSimLoop

    frames = [0]

    def tap(t: float, direction: str, bus: int, frame_id: int, data: bytes) -> None:
        frames[0] += 1

    loop = LeggedSimLoop()
    loop.set_goal(S.IN_CONTROL)
    for _ in range(20000):
        if loop.driver.state == S.IN_CONTROL:
            break
        loop.step()
    if loop.driver.state != S.IN_CONTROL:
        raise RuntimeError(f"the driver did not reach IN_CONTROL ({loop.driver.state})")
    loop.tap = tap
    n, every = round(seconds / loop.dt), round(0.05 / loop.dt)
    t0, cpu0 = time.perf_counter(), time.process_time()
    for i in range(n):
        if i % every == 0:
            loop.driver.set_velocity(0.5, 0.0, 0.2)
        loop.step()
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    if loop.driver.state != S.IN_CONTROL:
        raise RuntimeError(f"stopped trotting: {loop.driver.state}")
    loop.close()
    return wall, cpu, frames[0]


def simulated_rows(seconds: float, repeat: int) -> list[Row]:
    rows = []
    for label, fn, note in (
            ("lower computer alone", _lower_alone,
             "LeggedLower on a SimClock, trotting at 0.5 m/s, 0.2 rad/s; every frame encoded, "
             "none decoded; BMS polled"),
            ("lower computer + driver core", _with_driver,
             "LeggedSimLoop: every frame decoded by LeggedDriverCore, 50 Hz tick, the node's "
             "goal logic; cmd_vel 20 Hz")):
        runs = sorted(fn(seconds) for _ in range(repeat))
        wall, cpu, frames = runs[0]
        rows.append(Row("legged", f"simulated clock, {label}", seconds / wall,
                        "x real time", f"best of {repeat} (slowest {seconds / runs[-1][0]:.1f}x"
                        f"), {seconds:g} s trotting; by CPU time {seconds / cpu:.1f}x; "
                        f"{frames / seconds:,.0f} frames per simulated s; {note}"))
    return rows


def run(quick: bool = False) -> list[Row]:
    return (realtime_rows(3.0 if quick else 15.0)
            + simulated_rows(2.0 if quick else 10.0, 1 if quick else 3))
