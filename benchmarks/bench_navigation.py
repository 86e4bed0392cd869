"""Navigation benchmarks: the costmaps.

- global costmap inflation: the master grid rebuilt (static layer + inflation by the seed's
  footprint padded 0.1 m, inflation_radius 0.55 m), as after a set_footprint, on the shipped
  warehouse (600 x 400 cells) and on a synthetic 2000 x 2000 cell warehouse (100 x 100 m).
- local costmap update: one update cycle of the 5 x 5 m rolling window (moving the window,
  clearing and marking from the merged 720-beam /scan, footprint clearing, inflation) with the
  profile's two lidars, the robot mid-aisle in the warehouse; scans made beforehand.

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
    return rows


if __name__ == "__main__":
    from benchmarks.__main__ import table

    print(table(run()))
