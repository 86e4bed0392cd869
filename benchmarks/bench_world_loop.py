"""The whole simulated-clock loop: emulator + driver + world + localization in one process.

A WorldSim on the warehouse map drives the open lane along y = 2 m back and forth (8 m at
0.5 m/s, a half turn in place at up to 0.5 rad/s, and back) with the profile's lidars and
noise, the emulator's own odometry errors and amcl (particle filter) fed with the driver's
/odom. The drive is steered onto the lane from the true pose (an oracle driver, as a line
follower would be; without it the real track error walks the robot into the racks within two
minutes), so the rows measure localization, not the drive:

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
LANE_END = 12.0  #: [m] the lane runs from x = 4 to x = 12 at y = 2
SPEED = 0.5  #: [m/s]
TURN_RATE = 0.5  #: [rad/s]


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _twist(w: WorldSim, heading: float) -> tuple[float, float, bool]:
    """(linear, angular, leg done) toward the lane's end in ``heading`` (0 east, pi west)."""
    x, y, yaw = w.true_pose()
    err = _wrap(heading - yaw)
    if abs(err) > 0.1:  # turn in place onto the lane's heading first
        return 0.0, max(-TURN_RATE, min(TURN_RATE, 2.0 * err)), False
    east = math.cos(heading) > 0
    done = x >= LANE_END if east else x <= LANE[0]
    lateral = (LANE[1] - y) * (1.0 if east else -1.0)  # + = the lane lies to the left
    angular = max(-TURN_RATE, min(TURN_RATE, 1.5 * err + 1.0 * lateral))
    return (0.0 if done else SPEED), angular, done


def _drive(mode: str, seconds: float) -> tuple[float, list[float], list[float]]:
    w = WorldSim(WorldConfig(start=LANE, localization=mode, seed=1))
    w.run_until(lambda s: s.loop.driver.state == LinkState.READY, timeout=3.0)
    pos: list[float] = []
    yaw: list[float] = []
    dt = w.loop.mcu.dt
    every = round(0.2 / dt)
    command_every = max(1, round(0.05 / dt))  # twists at 20 Hz, as a navigation stack

    t0 = time.perf_counter()
    start = w.now
    heading = 0.0
    k = 0
    while w.now - start < seconds:
        if k % command_every == 0:
            linear, angular, done = _twist(w, heading)
            if done:
                heading = math.pi - heading  # back along the lane
            w.loop.driver.set_twist(linear, angular, False)
        w.step()
        k += 1
        if w.now > 5.0 and k % every == 0:
            e = w.localization_error()
            if e is not None:
                pos.append(e[0])
                yaw.append(math.degrees(e[1]))
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
