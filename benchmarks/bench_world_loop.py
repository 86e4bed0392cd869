"""The whole simulated-clock loop: emulator + driver + world + localization in one process.

A WorldSim on the warehouse map drives the open lane along y = 2 m back and forth (16 s at
0.5 m/s, a half turn at 0.5 rad/s, and back) with the profile's lidars and noise, the
emulator's own odometry errors and amcl (particle filter) fed with the driver's /odom:

- x real time: simulated seconds per wall second, for the particle filter and for the
  ground-truth localization mode (target >= 20x);
- the localization error of movebase_pose2d against the emulator's truth, sampled at 5 Hz
  after the first 5 s: p95 position and heading over 10 simulated minutes (1 with --quick).

Unlike bench_localization (synthetic odometry, scans only), this is the closed loop: the
odometry is the driver's EKF on the emulated wheels and IMU. ``python -m
benchmarks.bench_world_loop`` prints the rows.
"""

from __future__ import annotations

import math
import time

from benchmarks.common import Row, percentile
from lowerbase.driver.core import LinkState
from lowerbase.world.sim import WorldConfig, WorldSim

LANE = (4.0, 2.0, 0.0)
LEG = (0.5, 0.0, 16.0)      # linear [m/s], angular [rad/s], seconds
TURN = (0.0, 0.5, math.pi / 0.5)


def _drive(mode: str, seconds: float) -> tuple[float, list[float], list[float]]:
    w = WorldSim(WorldConfig(start=LANE, localization=mode, seed=1))
    w.run_until(lambda s: s.loop.driver.state == LinkState.READY, timeout=3.0)
    pos: list[float] = []
    yaw: list[float] = []
    every = round(0.2 / w.loop.mcu.dt)

    def sample(s: WorldSim) -> None:
        if s.now > 5.0 and round(s.now / s.loop.mcu.dt) % every == 0:
            e = s.localization_error()
            if e is not None:
                pos.append(e[0])
                yaw.append(math.degrees(e[1]))

    t0 = time.perf_counter()
    start = w.now
    while w.now - start < seconds:
        for linear, angular, dur in (LEG, TURN):
            w.drive(linear, angular, dur, on_step=sample)
    wall = time.perf_counter() - t0
    if w.contact_events:
        raise RuntimeError(f"the benchmark drive touched {w.contact_events[0].touched}")
    return (w.now - start) / wall, pos, yaw


def run(quick: bool = False) -> list[Row]:
    seconds = 60.0 if quick else 600.0
    speed, pos, yaw = _drive("filter", seconds)
    speed_truth, _, _ = _drive("truth", 60.0 if quick else 120.0)
    span = f"warehouse lane, {seconds / 60:g} simulated min"
    return [
        Row("world loop", "emulator + driver + world + amcl, x real time", round(speed, 1), "x",
            f"{span}; target >= 20x"),
        Row("world loop", "emulator + driver + world, ground-truth localization, x real time",
            round(speed_truth, 1), "x", "same drive"),
        Row("world loop", "closed-loop localization error p95 (position)",
            round(percentile(pos, 95) * 100, 2), "cm", f"{span}; 5 Hz samples after 5 s"),
        Row("world loop", "closed-loop localization error p95 (heading)",
            round(percentile(yaw, 95), 3), "deg", span),
    ]


if __name__ == "__main__":
    for row in run(quick=True):
        print(row)
