"""Trace navigation benchmarks (lowerbase.trace, shared/seeds/001), on the simulated clock.

- cross-track p95: TraceNavigate follows a straight route along the warehouse's bottom corridor
  at 0.5 m/s (10 m; quick: 5 m); the emulator's true pose against the line, sampled every
  control period from 1 m after the start to 0.5 m before the end. Ground-truth localization
  (the module, not amcl, is measured). Target <= 3 cm.
- cancel -> zero speed on the bus: while the route runs, the empty list is published at sim time
  t0; the first MotionCommand frame (driver_base -> lower computer, tapped on the simulated
  bus) with Linear = Angular = 0 after t0, decoded from its bytes. Max and p50 over
  ``CANCELS`` (quick: 3) cancels at different phases of the control period. Target <= 100 ms.
- protobuf/bridge overhead: wall time per message of encode + decode (the
  ``lowerbase_msgs/Protobuf`` envelope's bytes) of a GTraceList of 10 and 100 segments, and of
  a 720-beam /scan through the laser bridge (LaserScan -> GLaserScan -> bytes -> back).

``python -m benchmarks.bench_trace [--quick]`` prints the rows.
"""

from __future__ import annotations

import itertools
import struct
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from benchmarks.common import Row, percentile

if TYPE_CHECKING:
    from lowerbase.trace.sim import TraceSim

Y = 1.2  #: the corridor's route line
MOTION_COMMAND = 32  #: chassis.dbc: Linear, Angular int16 LE x 0.001


def _route(xs: list[float], speed: int = 500) -> Any:
    from lowerbase.trace import messages as m

    lst = m.GTraceList(map=b"warehouse")
    for a, b in itertools.pairwise(xs):
        s = lst.lists.add(finished=0.0)
        s.first.x, s.first.y, s.first.angle, s.first.speed = a, Y, 0.0, speed
        s.second.x, s.second.y, s.second.angle = b, Y, 0.0
    return lst


def _sim(tap: Callable[[float, str, int, bytes], None] | None = None) -> TraceSim:
    from lowerbase.simloop.loop import SimLoop
    from lowerbase.trace.base import TraceParams
    from lowerbase.trace.sim import TraceSim
    from lowerbase.world.sim import WorldConfig, WorldSim

    world = WorldSim(WorldConfig(map="warehouse", start=(6.0, Y, 0.0), localization="truth"),
                     loop=SimLoop(tap=tap))
    return TraceSim(params=TraceParams(map_name="warehouse"), world=world)


def cross_track(length: float) -> tuple[float, float, int]:
    """(p95, max) |cross-track| [m] and the number of samples."""
    from lowerbase.trace import messages as m
    from lowerbase.trace.sim import ROUTE, STATUS

    sim = _sim()
    end = 6.0 + length
    sim.publish(ROUTE, _route([6.0, end]))
    errors: list[float] = []

    def done() -> bool:
        x, y, _ = sim.world.true_pose()
        if 7.0 <= x <= end - 0.5:
            errors.append(abs(y - Y))
        return any(r.status == m.FINISHED
                   for _, r in sim.published[STATUS])

    sim.run_until(done, length / 0.5 + 30.0)
    return percentile(errors, 95), max(errors), len(errors)


def cancel_latencies(cancels: int) -> list[float]:
    """[s] from the empty list to the first zero MotionCommand on the bus, per cancel."""
    from lowerbase.trace import messages as m
    from lowerbase.trace.sim import ROUTE

    frames: list[tuple[float, float, float]] = []

    def tap(t: float, direction: str, frame_id: int, data: bytes) -> None:
        if direction == "upper" and frame_id == MOTION_COMMAND:
            lin, ang = struct.unpack_from("<hh", data)
            frames.append((t, lin * 1e-3, ang * 1e-3))

    sim = _sim(tap)
    out = []
    for k in range(cancels):
        sim.publish(ROUTE, _route([6.0 + 2.0 * k, 30.0]))
        sim.run(2.0 + 0.013 * k)  # moving; the phase varies
        t0 = sim.now
        sim.publish(ROUTE, m.GTraceList(map=b"warehouse"))
        sim.run(0.5)
        zero = next((t for t, v, w in frames if t >= t0 and v == 0.0 and w == 0.0), None)
        out.append(float("inf") if zero is None else zero - t0)
        sim.run(1.0)  # at rest before the next one
    return out


def _per_call(fn: Callable[[], object], calls: int) -> float:
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return best


def overhead(calls: int) -> list[tuple[str, float]]:
    """(what, wall seconds per message)."""
    from lowerbase.trace import messages as m
    from lowerbase.trace.bridges import laser_from_pb, laser_to_pb
    from lowerbase.world.lidar import LaserScan

    out = []
    for n in (10, 100):
        lst = _route([float(i) for i in range(n + 1)])

        def trip(lst: Any = lst) -> object:
            return m.decode(*m.encode(lst), m.GTraceList)

        out.append((f"GTraceList of {n} segments", _per_call(trip, calls)))
    scan = LaserScan("base_link", 1.0, -np.pi, np.pi, 2 * np.pi / 720, 0.0, 0.1, 0.05, 30.0,
                     np.linspace(0.5, 20.0, 720, dtype=np.float32))

    def bridge() -> object:
        msg = m.decode(*m.encode(laser_to_pb(scan)), m.GLaserScan)
        return laser_from_pb(msg)

    out.append(("/scan 720 beams through the laser bridge", _per_call(bridge, calls)))
    return out


def run(quick: bool = False) -> list[Row]:
    rows = []
    length = 5.0 if quick else 10.0
    p95, worst, n = cross_track(length)
    rows.append(Row("trace", "cross-track p95, straight at 0.5 m/s", p95 * 100, "cm",
                    f"max {worst * 100:.2f} cm over {n} samples of a {length:g} m segment; "
                    "target <= 3"))
    lat = cancel_latencies(3 if quick else 10)
    rows.append(Row("trace", "empty list -> zero MotionCommand on the bus", max(lat) * 1000,
                    "ms", f"max of {len(lat)} (p50 {percentile(lat, 50) * 1000:.0f} ms), "
                    "simulated clock; target <= 100"))
    for what, sec in overhead(200 if quick else 2000):
        rows.append(Row("trace", f"protobuf encode+decode: {what}", sec * 1e6, "us",
                        "wall time per message, best of 3"))
    return rows


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(f"{r.group:8} {r.name:55} {r.value:10.3f} {r.unit:4} {r.note}")
