"""Localization benchmarks: cost per filter update, accuracy over a drive, re-localization time.

- cost: ``Localizer.update`` with a fixed particle count (500 / 2000, KLD off) and 60 beams on
  the warehouse map, scans made beforehand (ray casting not counted), best of 3.
- accuracy: a drive through the warehouse aisles at 0.5 m/s (10 simulated minutes; 1 with
  --quick) with the profile's lidars (two nanoScan3, 12 mm range noise, merged 720-beam scan)
  and odometry drifting by a 1 % distance and 2 % heading scale error; the error of the
  published pose (map -> odom composed with /odom, as movebase_pose2d) against the truth,
  sampled at 5 Hz: p95 position and heading (targets <= 5 cm, <= 1 deg).
- kidnap: after 60 s on the drive the robot is carried to another aisle; the simulated
  time, driving on, until the estimate is within 15 cm and not 'lost' for 5 updates running.

``run()`` returns rows; ``python -m benchmarks.bench_localization`` prints them.
"""

from __future__ import annotations

import itertools
import math
import time

import numpy as np
from scipy.ndimage import distance_transform_edt

from benchmarks.common import Row, percentile
from lowerbase.clock import SimClock
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import LaserScan, LidarRig
from lowerbase.world.localization import AmclParams, Localizer
from lowerbase.world.localization.poses import Pose2D, compose, inverse, wrap_scalar
from lowerbase.world.maps import load_map
from lowerbase.world.raycast import Scene
from lowerbase.world.sensors import sensors_from_profile_file

DT = 0.2  # [s] sampling step of the drive (5 Hz)
SPEED = 0.5  # [m/s]
#: a serpentine through the warehouse aisles and back along the open bottom area
TOUR: list[tuple[float, float]] = [
    (4.0, 2.0), (28.6, 2.0), (28.6, 4.75), (7.6, 4.75), (7.6, 7.25), (28.6, 7.25),
    (28.6, 9.75), (6.0, 9.75), (6.0, 2.0), (4.0, 2.0)]


def tour_poses(seconds: float, start: int = 0) -> list[Pose2D]:
    """Truth poses every DT along TOUR (repeated), turning in place at 1 rad/s at corners."""
    out: list[Pose2D] = []
    pts = TOUR[start:] + TOUR[1:start + 1] if start else TOUR
    x, y = pts[0]
    yaw = math.atan2(pts[1][1] - y, pts[1][0] - x)
    while len(out) * DT < seconds:
        for (x0, y0), (x1, y1) in itertools.pairwise(pts):
            heading = math.atan2(y1 - y0, x1 - x0)
            turn = wrap_scalar(heading - yaw)
            n = max(1, math.ceil(abs(turn) / (1.0 * DT)))
            out += [(x0, y0, wrap_scalar(yaw + turn * (i + 1) / n)) for i in range(n)]
            yaw = heading
            steps = max(1, math.ceil(math.hypot(x1 - x0, y1 - y0) / (SPEED * DT)))
            out += [(x0 + (x1 - x0) * (i + 1) / steps, y0 + (y1 - y0) * (i + 1) / steps, heading)
                    for i in range(steps)]
    return out[: int(seconds / DT)]


def check_clearance(grid: OccupancyGrid, poses: list[Pose2D], clearance: float = 0.35) -> None:
    dist = distance_transform_edt(~grid.occupied()) * grid.resolution
    xs = np.array([p[0] for p in poses])
    ys = np.array([p[1] for p in poses])
    col, row = grid.world_to_cell(xs, ys)
    if float(dist[row, col].min()) < clearance:
        raise RuntimeError("the benchmark tour passes too close to an obstacle")


def odometry(truth: list[Pose2D], teleport: int | None = None) -> list[Pose2D]:
    """Wheel odometry of the truth: 1 % distance and 2 % heading scale error; blind to a
    teleport at index ``teleport``."""
    odom: list[Pose2D] = [(0.0, 0.0, 0.0)]
    for i in range(1, len(truth)):
        if i == teleport:
            odom.append(odom[-1])
            continue
        dx, dy, dyaw = compose(inverse(truth[i - 1]), truth[i])
        odom.append(compose(odom[-1], (dx * 1.01, dy * 1.01, dyaw * 1.02)))
    return odom


class _Drive:
    """Scans only when the localizer will update (amcl's thresholds), to spare ray casting."""

    def __init__(self, grid: OccupancyGrid, loc: Localizer, rig: LidarRig) -> None:
        self.scene = Scene(grid)
        self.loc, self.rig = loc, rig
        self.ref: Pose2D | None = None

    def step(self, truth: Pose2D, odom: Pose2D, t: float) -> bool:
        p = self.loc.params
        ref = self.ref
        if ref is not None and math.hypot(odom[0] - ref[0], odom[1] - ref[1]) < p.update_min_d \
                and abs(wrap_scalar(odom[2] - ref[2])) < p.update_min_a:
            return False
        self.ref = odom
        return self.loc.update(odom, self.rig.scan(self.scene, truth, t)) is not None


def _rig() -> LidarRig:
    cfg = sensors_from_profile_file()
    return LidarRig(cfg.lidars, cfg.scan)


def bench_cost(grid: OccupancyGrid, n_updates: int) -> list[Row]:
    rig = _rig()
    scene = Scene(grid)
    truth = tour_poses(2 * n_updates)[::2][:n_updates]
    odom = odometry(truth)
    scans: list[LaserScan] = [rig.scan(scene, p, 0.0) for p in truth]
    rows = []
    for n in (500, 2000):
        params = AmclParams(kld_sampling=False, min_particles=n, max_particles=n,
                            update_min_d=0.0, update_min_a=0.0, laser_max_beams=60)
        best = math.inf
        for _ in range(3):
            loc = Localizer(grid, params, clock=SimClock(), seed=1, initial_pose=truth[0],
                            initial_cov=np.diag([0.01, 0.01, 0.003]))
            t0 = time.perf_counter()
            for o, s in zip(odom, scans, strict=True):
                loc.update(o, s)
            best = min(best, (time.perf_counter() - t0) / n_updates)
        rows.append(Row("localization", f"filter update, {n} particles x 60 beams",
                        round(best * 1000, 2), "ms", "warehouse 600x400 cells, KLD off"))
    return rows


def bench_accuracy(grid: OccupancyGrid, seconds: float) -> list[Row]:
    truth = tour_poses(seconds)
    check_clearance(grid, truth)
    odom = odometry(truth)
    clock = SimClock()
    loc = Localizer(grid, clock=clock, seed=2, initial_pose=truth[0],
                    initial_cov=np.diag([0.05 ** 2, 0.05 ** 2, math.radians(2) ** 2]))
    drive = _Drive(grid, loc, _rig())
    pos, yaw = [], []
    lost = 0
    t0 = time.perf_counter()
    for tp, op in zip(truth, odom, strict=True):
        drive.step(tp, op, clock.advance(DT))
        est = loc.pose_from_odom(op)
        if est is None:
            continue
        pos.append(math.hypot(est[0] - tp[0], est[1] - tp[1]))
        yaw.append(abs(math.degrees(wrap_scalar(est[2] - tp[2]))))
        lost += bool(loc.last and loc.last.lost)
    wall = time.perf_counter() - t0
    odo_end = compose(compose(truth[0], inverse(odom[0])), odom[-1])
    drift = math.hypot(odo_end[0] - truth[-1][0], odo_end[1] - truth[-1][1])
    note = (f"{seconds / 60:.0f} min drive at 0.5 m/s, {loc.stats.filter_updates} updates, "
            f"{len(pos)} samples")
    return [
        Row("localization", "position error p95", round(percentile(pos, 95) * 100, 2), "cm",
            f"target <= 5 cm; {note}; max {max(pos) * 100:.1f} cm"),
        Row("localization", "heading error p95", round(percentile(yaw, 95), 3), "deg",
            f"target <= 1 deg; max {max(yaw):.2f} deg"),
        Row("localization", "updates reading 'lost'", round(100 * lost / max(len(pos), 1), 2),
            "%", f"odometry alone ends {drift:.2f} m off"),
        Row("localization", "drive incl. ray casting", round(seconds / wall, 2), "x real time",
            "the profile's two lidars cast only at filter updates"),
    ]


def bench_kidnap(grid: OccupancyGrid, seconds: float) -> list[Row]:
    before = tour_poses(60.0)
    after = tour_poses(seconds, start=7)
    truth = before + after
    check_clearance(grid, truth)
    jump = len(before)
    odom = odometry(truth, teleport=jump)
    clock = SimClock()
    # augmented MCL on, with amcl's suggested values (the default is off, as amcl's)
    recovery = AmclParams(recovery_alpha_slow=0.001, recovery_alpha_fast=0.1)
    loc = Localizer(grid, recovery, clock=clock, seed=3, initial_pose=truth[0],
                    initial_cov=np.diag([0.05 ** 2, 0.05 ** 2, math.radians(2) ** 2]))
    drive = _Drive(grid, loc, _rig())
    detected = recovered = math.nan
    good = 0
    for i, (tp, op) in enumerate(zip(truth, odom, strict=True)):
        updated = drive.step(tp, op, clock.advance(DT))
        if i < jump or not updated or loc.last is None:
            continue
        t = (i - jump) * DT
        if loc.last.lost and math.isnan(detected):
            detected = t
        ok = math.hypot(loc.last.pose[0] - tp[0], loc.last.pose[1] - tp[1]) < 0.15 \
            and not loc.last.lost
        good = good + 1 if ok else 0
        if good == 5:
            recovered = t
            break
    carried = math.hypot(after[0][0] - before[-1][0], after[0][1] - before[-1][1])
    return [
        Row("localization", "kidnap: detected ('lost') after", detected, "s",
            f"carried {carried:.1f} m at t = 60 s"),
        Row("localization", "kidnap: re-localized after", recovered, "s",
            f"augmented MCL (0.001 / 0.1), driving on; n/a: not within {seconds:.0f} s"),
    ]


def run(quick: bool = False) -> list[Row]:
    grid = load_map("warehouse")
    return [*bench_cost(grid, 20 if quick else 60),
            *bench_accuracy(grid, 60.0 if quick else 600.0),
            *bench_kidnap(grid, 120.0 if quick else 300.0)]


if __name__ == "__main__":
    for row in run():
        print(f"{row.name:<45} {row.value:>10} {row.unit:<12} {row.note}")
