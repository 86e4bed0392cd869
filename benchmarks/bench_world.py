"""World sensor benchmarks: the merged /scan and the depth camera on a 1000 x 1000 cell map.

The map is a synthetic warehouse (50 x 50 m at 0.05 m: outer walls, shelf rows with 2.2 m
aisles and cross aisles), the robot mid-aisle facing along it; the sensors are the default
profile's (two nanoScan3 merged into a 720-beam /scan, a D435 at 640 x 480). Costs are CPU time
per message (``time.process_time``, one thread), and the share of one core at the sensor's rate;
the ray casters' distance field, built once per map, is reported on its own, and so are the map
cast alone (the numba kernel against its numpy reference) and the kernel's first-cast cost in a
new process (compiling it into an empty cache, then loading it from the cache).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

import numpy as np

from benchmarks.common import Row


def warehouse_grid() -> object:
    from lowerbase.world.grid import OccupancyGrid

    data = np.zeros((1000, 1000), np.int8)
    data[:4, :] = data[-4:, :] = data[:, :4] = data[:, -4:] = 100
    for y0 in range(60, 940, 60):          # shelf rows 0.8 m deep every 3 m
        for x0 in range(60, 940, 220):     # 10 m long, 1 m cross aisles
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


_FIRST_CAST = """
import time
import numpy as np
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.raycast import cast_grid
grid = OccupancyGrid(np.zeros((4, 4), np.int8), 0.05)
t0 = time.process_time()
cast_grid(grid.occupied(), grid, 0.1, 0.1, np.zeros(3), 1.0)
print(time.process_time() - t0)
"""


def _first_cast_s(cache_dir: str) -> float:
    """CPU seconds of a new process's first cast (numba's import and the kernel's compile or
    cache load) with the kernel cached in ``cache_dir``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run([sys.executable, "-c", _FIRST_CAST], env=env, check=True,
                         capture_output=True, text=True).stdout
    return float(out.split()[-1])


def run(quick: bool = False) -> list[Row]:
    from lowerbase.world.camera import DepthCamera
    from lowerbase.world.lidar import LidarRig
    from lowerbase.world.raycast import Scene, Solid, cast_grid
    from lowerbase.world.raycast_reference import cast_grid_reference
    from lowerbase.world.sensors import SensorsConfig

    config = SensorsConfig()
    box = Solid(0.6, polygon=np.array([[14.0, 4.4], [14.6, 4.4], [14.6, 5.0], [14.0, 5.0]]))
    person = Solid(1.7, circle=(16.0, 4.9, 0.25))
    scene = Scene(warehouse_grid(), solids=(box, person))  # type: ignore[arg-type]
    pose = (11.0, 4.9, 0.05)    # mid-aisle (shelves at y 3.0-3.8 and 6.0-6.8 m), along it
    import scipy.ndimage  # noqa: F401  (imported before the clock starts)

    t0 = time.process_time()
    _ = scene.grid_field                # the ray casters' distance field: once per map
    field_s = time.process_time() - t0
    rig = LidarRig(config.lidars, config.scan)
    n = 20 if quick else 100

    def moving_scan(k: int) -> object:
        rig._last_cast = None  # a robot that moves: the map is cast for every scan
        return rig.scan(scene, pose, k * 0.04)

    scan_s = _cpu_per_call(moving_scan, n)
    beams = sum(lc.beams for lc in config.lidars)
    rows = [
        Row("world", f"/scan: {len(config.lidars)} lidars ({beams} beams) merged into "
                     f"{config.scan.beams}, 1000x1000 map", scan_s * 1e3, "ms CPU/scan"),
        Row("world", f"/scan CPU at {rig.rate_hz:g} Hz", scan_s * rig.rate_hz * 100,
            "% of one core", "target < 20 %"),
        Row("world", "ray-casting distance field of the 1000x1000 map (once per map)",
            field_s * 1e3, "ms CPU"),
    ]
    rays = [lidar.rays(pose) for lidar in rig.lidars]
    xs = np.concatenate([np.full(a.size, x) for x, _, a in rays])
    ys = np.concatenate([np.full(a.size, y) for _, y, a in rays])
    angles = np.concatenate([a for *_, a in rays])
    casters: tuple[tuple[str, Callable[..., object]], ...] = (
        ("numba kernel", cast_grid), ("numpy reference", cast_grid_reference))
    for name, cast in casters:
        def cast_map(_k: int, cast: Callable[..., object] = cast) -> object:
            return cast(scene.mask, scene.grid, xs, ys, angles, 40.0, scene.grid_field)

        cast_s = _cpu_per_call(cast_map, n)
        rows.append(Row("world", f"the map cast alone ({angles.size} rays), {name}",
                        cast_s * 1e3, "ms CPU/scan"))
    with tempfile.TemporaryDirectory(prefix="lowerbase-numba-") as cache_dir:
        compile_s = _first_cast_s(cache_dir)
        cached_s = _first_cast_s(cache_dir)
    rows += [
        Row("world", "first cast in a new process: numba import + kernel compile", compile_s,
            "s CPU", "an empty cache (once per install)"),
        Row("world", "first cast in a new process: numba import + cached kernel", cached_s,
            "s CPU"),
    ]
    if config.camera is not None:
        camera = DepthCamera(config.camera)
        frame_s = _cpu_per_call(lambda k: camera.render(scene, pose, k * 0.1), 3 if quick else 10)
        size = f"{config.camera.width}x{config.camera.height}"
        rows += [
            Row("world", f"depth camera {size}: depth, colour, points, cloud_without_planes",
                frame_s * 1e3, "ms CPU/frame"),
            Row("world", f"depth camera {size} CPU at 10 Hz", frame_s * 10 * 100,
                "% of one core", "target: 10 Hz affordable (< 100 %)"),
        ]
    return rows


if __name__ == "__main__":
    for row in run():
        print(row)
