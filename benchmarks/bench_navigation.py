"""Navigation benchmarks: the costmaps.

- global costmap inflation: the master grid rebuilt (static layer + inflation by the seed's
  footprint padded 0.1 m, inflation_radius 0.55 m), as after a set_footprint, on the shipped
  warehouse (600 x 400 cells) and on a synthetic 2000 x 2000 cell warehouse (100 x 100 m).
- local costmap update: one update cycle of the 5 x 5 m rolling window (moving the window,
  clearing and marking from the merged 720-beam /scan, footprint clearing, inflation) with the
  profile's two lidars, the robot mid-aisle in the warehouse; scans made beforehand.

- make_plan (the Navigator's, on the global costmap inflated to 1.0 m): p50/p99 over random
  start/goal pairs on free cells, on the warehouse and on the 2000 x 2000 cell map.
- random goals: ``GOALS`` (quick: 5) random reachable goals one after the other on the
  warehouse, amcl localization on, through the whole chain (NavSim on a WorldSim): share reached,
  collisions (the goals not reached listed with their reasons), accuracy p95 against the
  emulator's truth, time to goal p50, and the simulated clock's speed of the whole loop with
  navigation (simulated seconds per CPU second).
- StepControl: ``STEPS`` (quick: 10) random straight/rotate steps driven by StepController on a
  WorldSim; the error of each step against the emulator's truth (max and p95).

CPU time per call, best of 3 runs. ``python -m benchmarks.bench_navigation`` prints the rows.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from benchmarks.common import Row


def big_warehouse(cells: int = 2000) -> object:
    from lowerbase.world.grid import OccupancyGrid

    data = np.zeros((cells, cells), np.int8)
    data[:4, :] = data[-4:, :] = data[:, :4] = data[:, -4:] = 100
    for y0 in range(60, cells - 60, 60):        # shelf rows 0.8 m deep every 3 m
        for x0 in range(60, cells - 60, 220):   # 10 m long, 1 m cross aisles
            data[y0:y0 + 16, x0:x0 + 200] = 100
    return OccupancyGrid(data, 0.05)


def _cpu_per_call(fn: Callable[[int], object], calls: int, repeat: int = 3) -> float:
    """Best-of-``repeat`` CPU seconds per call."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        for k in range(calls):
            fn(k)
        best = min(best, (time.process_time() - t0) / calls)
    return best


def run(quick: bool = False) -> list[Row]:
    from lowerbase.navigation.costmap import global_costmap, local_costmap
    from lowerbase.world.footprint import DEFAULT_POINTS
    from lowerbase.world.grid import OccupancyGrid
    from lowerbase.world.lidar import LidarRig
    from lowerbase.world.maps import load_map
    from lowerbase.world.raycast import Scene
    from lowerbase.world.sensors import SensorsConfig

    def rebuild(cm: object) -> Callable[[int], object]:
        def once(_: int) -> object:
            cm.set_footprint(DEFAULT_POINTS)  # type: ignore[attr-defined]
            return cm.costs  # type: ignore[attr-defined]
        return once

    rows: list[Row] = []
    warehouse = load_map("warehouse")
    big = big_warehouse()
    assert isinstance(big, OccupancyGrid)
    for name, grid, calls in (("warehouse map", warehouse, 5 if quick else 20),
                              ("2000x2000 map", big, 1 if quick else 3)):
        cm = global_costmap(grid)
        s = _cpu_per_call(rebuild(cm), calls)
        rows.append(Row("navigation", f"global costmap inflation, {name} "
                        f"({grid.width}x{grid.height} cells)", s * 1e3, "ms CPU"))

    config = SensorsConfig()
    rig = LidarRig(config.lidars, config.scan)
    scene = Scene(warehouse)
    poses = [(4.0 + 0.02 * k, 2.0, 0.0) for k in range(20 if quick else 100)]
    scans = [rig.scan(scene, p, 0.04 * k) for k, p in enumerate(poses)]
    local = local_costmap(None, poses[0])

    def update(k: int) -> object:
        local.update(poses[k], scan=scans[k])
        return local.costs

    s = _cpu_per_call(update, len(poses))
    rows.append(Row("navigation", f"local costmap update, 5x5 m window, "
                    f"{config.scan.beams}-beam /scan", s * 1e3, "ms CPU",
                    f"{s * rig.rate_hz * 100:.1f} % of one core at {rig.rate_hz:g} Hz"))
    rows += plan_rows(warehouse, big, 10 if quick else 50)
    rows += goal_rows(5 if quick else GOALS)
    rows += step_rows(10 if quick else STEPS)
    return rows


GOALS = 100
STEPS = 50


def _free_poses(nav: object, rng: np.random.Generator, n: int) -> list[tuple[float, float,
                                                                            float]]:
    """``n`` random poses on cells of zero cost (clear of every inflation)."""
    costs = np.asarray(nav.global_costmap.costs)  # type: ignore[attr-defined]
    rows, cols = np.nonzero(costs == 0)
    pick = rng.choice(len(rows), size=n)
    res, (ox, oy) = nav.grid.resolution, nav.global_costmap.origin  # type: ignore[attr-defined]
    return [(ox + (cols[k] + 0.5) * res, oy + (rows[k] + 0.5) * res,
             float(rng.uniform(-np.pi, np.pi))) for k in pick]


def plan_rows(warehouse: object, big: object, count: int) -> list[Row]:
    from benchmarks.common import percentile
    from lowerbase.navigation.navigator import Navigator

    rows: list[Row] = []
    for name, grid in (("warehouse", warehouse), ("2000x2000 map", big)):
        nav = Navigator(grid)  # type: ignore[arg-type]
        rng = np.random.default_rng(1)
        pairs = list(zip(_free_poses(nav, rng, count), _free_poses(nav, rng, count),
                         strict=True))
        times, found = [], 0
        for start, goal in pairs:
            t0 = time.process_time()
            found += nav.make_plan(start, goal).ok
            times.append((time.process_time() - t0) * 1e3)
        rows.append(Row("navigation", f"make_plan p50, {name}", percentile(times, 50),
                        "ms CPU", f"p99 {percentile(times, 99):.0f} ms; {found}/{count} "
                        f"random pairs have a path"))
    return rows


def goal_rows(count: int) -> list[Row]:
    import math

    from benchmarks.common import percentile
    from lowerbase.navigation.navigator import GoalState
    from lowerbase.navigation.sim import NavSim
    from lowerbase.world.sim import WorldConfig, WorldSim

    world = WorldSim(WorldConfig(map="warehouse", start="start", localization="filter"))
    world.run(1.0)
    sim = NavSim(world)
    rng = np.random.default_rng(7)
    reached = collisions = 0
    errors, times = [], []
    failed: list[str] = []  #: "#k state: reason" of each goal not reached
    t0, s0 = time.process_time(), world.now
    done = 0
    while done < count:
        goal = _free_poses(sim.navigator, rng, 1)[0]
        if not sim.navigator.make_plan(sim.pose(), goal).ok:
            continue  # not reachable from here: draw another
        done += 1
        run = sim.go_to(goal, timeout=180.0)
        collisions += run.contacts > 0
        if run.state is not GoalState.SUCCEEDED:
            failed.append(f"#{done} {run.state.name.lower()}: {run.reason}")
        else:
            reached += 1
            x, y, _ = world.true_pose()
            errors.append(math.hypot(x - goal[0], y - goal[1]) * 100)
            times.append(run.duration)
    cpu = time.process_time() - t0
    speed = (world.now - s0) / cpu
    return [
        Row("navigation", f"random goals reached, warehouse, amcl ({count} goals)",
            100.0 * reached / count, "%", f"target >= 99 %; {collisions} with contact "
            f"(target 0)" + (f"; not reached: {'; '.join(failed)}" if failed else "")),
        Row("navigation", "goal accuracy p95 (truth)", percentile(errors, 95), "cm",
            f"time to goal p50 {percentile(times, 50):.0f} s"),
        Row("navigation", "simulated clock, whole loop with navigation", speed,
            "x real time (CPU)", "target >= 20x; simulated s per CPU s of WorldSim + amcl + "
            "costmaps + planner + controller"),
    ]


def step_rows(count: int) -> list[Row]:
    import math

    from benchmarks.common import percentile
    from lowerbase.navigation.controller import Limits, wrap
    from lowerbase.navigation.steps import EXCUTE, ROTATE, STRAIGHT, Step, StepController
    from lowerbase.world.sim import WorldConfig, WorldSim

    world = WorldSim(WorldConfig(map="empty_room", start=(5.0, 4.3, 0.0), localization="off"))
    world.run(1.0)
    ctl = StepController(Limits.from_parameters(world.loop.driver.parameters))
    rng = np.random.default_rng(11)
    dist_err, ang_err = [], []
    for _ in range(count):
        before = world.true_pose()
        if rng.random() < 0.5:
            # towards the room's centre, so that the robot stays clear of the walls
            ahead = (5.0 - before[0]) * math.cos(before[2]) + (4.3 - before[1]) * \
                math.sin(before[2])
            dist = math.copysign(float(rng.uniform(0.2, 1.5)), ahead if ahead else 1.0)
            step = Step(STRAIGHT, dist, float(rng.choice([0.0, 0.3, 0.5])))
        else:
            step = Step(ROTATE, float(rng.uniform(-3.0, 3.0)), float(rng.choice([0.0, 0.5])))
        ctl.goal(EXCUTE, [step])
        end = world.now + 60.0
        while ctl.active and world.now < end:
            odom = world.odom_pose()
            v, w = ctl.tick(odom if odom is not None else (0.0, 0.0, 0.0))
            world.loop.driver.set_twist(v, w)
            world.run(0.05)
        world.drive(0.0, 0.0, 0.5)
        after = world.true_pose()
        if step.execute_mode == STRAIGHT:
            moved = (after[0] - before[0]) * math.cos(before[2]) + \
                (after[1] - before[1]) * math.sin(before[2])
            dist_err.append(abs(moved - step.data) * 1000)
        else:
            ang_err.append(math.degrees(abs(wrap(after[2] - before[2] - step.data))))
    return [
        Row("navigation", f"StepControl straight error p95 (truth, {len(dist_err)} steps)",
            percentile(dist_err, 95), "mm", f"max {max(dist_err, default=0):.1f} mm; "
            f"target 10 mm"),
        Row("navigation", f"StepControl rotate error p95 (truth, {len(ang_err)} steps)",
            percentile(ang_err, 95), "deg", f"max {max(ang_err, default=0):.2f} deg; "
            f"target 0.5 deg"),
    ]


if __name__ == "__main__":
    from benchmarks.__main__ import table

    print(table(run()))
