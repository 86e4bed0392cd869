"""2D lidars on the base, ray-cast against the map and the obstacles, merged into one /scan.

Each :class:`Lidar` casts its beams from its mounting pose (numpy, :mod:`raycast`), adds the
datasheet's range noise and dropouts from its own seeded generator, and reports in REP-117
terms: ``+inf`` no return within ``range_max``, ``-inf`` a return closer than ``range_min``,
``NaN`` a dropout (no valid measurement). :class:`ScanMerger` then does what the real chassis'
"fusion of multiple lidars" does (as ira_laser_tools' laserscan_multi_merger): every valid return
is projected into ``base_link`` and each merged beam takes the nearest return whose bearing from
the base origin falls into it. The scan's motion during one sweep is not modelled.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lowerbase.errors import ConfigError, WorldError
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.raycast import (
    GridField,
    Rays,
    Scene,
    cast_grid,
    cast_rays_prepared,
    cast_solids,
    solids_taller_than,
)

TWO_PI = 2.0 * math.pi
#: one scan's random numbers: range noise (standard normal), dropouts (uniform) or None
Draws = tuple[np.ndarray, np.ndarray | None]


@dataclass(frozen=True)
class LaserScan:
    """sensor_msgs/LaserScan without ROS (angles [rad], ranges [m] float32, stamp [s])."""

    frame_id: str
    stamp: float
    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float
    scan_time: float
    range_min: float
    range_max: float
    ranges: np.ndarray

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + np.arange(self.ranges.size) * self.angle_increment


def _check(name: str, key: str, value: float, lo: float, hi: float, unit: str,
           lo_open: bool = False) -> None:
    ok = math.isfinite(value) and (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        bound = f"{'>' if lo_open else '>='} {lo:g} and <= {hi:g}"
        raise ConfigError(f"lidar {name!r}: {key} = {value!r} is invalid; allowed: {bound}{unit}")


@dataclass(frozen=True)
class LidarConfig:
    """One 2D lidar. Angles in radians, lengths in metres; mounting pose on ``base_link``."""

    name: str = "front"
    frame_id: str = "laser_front"
    x: float = 0.0
    y: float = 0.0
    z: float = 0.2                 # scan plane height above the floor
    yaw: float = 0.0
    fov: float = math.radians(275.0)
    angular_step: float = math.radians(0.16666667)  # 1/6 deg as default.toml writes it
    range_min: float = 0.05
    range_max: float = 40.0
    rate_hz: float = 25.0
    range_sigma: float = 0.012     # [m] 1-sigma range noise at 0 m ...
    range_sigma_per_m: float = 0.0  # ... growing by this many metres per metre of range
    dropout_prob: float = 0.0      # probability that a beam has no valid measurement (NaN)
    seed: int = 1

    def __post_init__(self) -> None:
        n = self.name
        if not self.name or not self.frame_id:
            raise ConfigError("lidar name and frame_id must be non-empty")
        for key in ("x", "y", "yaw"):
            _check(n, key, getattr(self, key), -100.0, 100.0, "")
        _check(n, "z", self.z, 0.0, 10.0, " m")
        _check(n, "fov", self.fov, 0.0, TWO_PI, " rad", lo_open=True)
        _check(n, "angular_step", self.angular_step, 0.0, self.fov, " rad", lo_open=True)
        _check(n, "range_min", self.range_min, 0.0, 1000.0, " m")
        _check(n, "range_max", self.range_max, self.range_min, 1000.0, " m", lo_open=True)
        _check(n, "rate_hz", self.rate_hz, 0.0, 1000.0, " Hz", lo_open=True)
        _check(n, "range_sigma", self.range_sigma, 0.0, 10.0, " m")
        _check(n, "range_sigma_per_m", self.range_sigma_per_m, 0.0, 1.0, "")
        _check(n, "dropout_prob", self.dropout_prob, 0.0, 1.0, "")
        if self.dropout_prob >= 1.0:
            raise ConfigError(f"lidar {n!r}: dropout_prob = 1 leaves no measurement; "
                              f"allowed: >= 0 and < 1")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError(f"lidar {n!r}: seed = {self.seed!r} must be an integer >= 0")
        if self.beams < 1 or self.beams > 100_000:
            raise ConfigError(f"lidar {n!r}: fov / angular_step gives {self.beams} beams; "
                              f"allowed: 1..100000")

    @property
    def beams(self) -> int:
        full = self.fov >= TWO_PI - 1e-9
        steps = self.fov / self.angular_step
        return round(steps) if full else math.floor(steps + 1e-4) + 1

    @property
    def angle_min(self) -> float:
        return -math.pi if self.fov >= TWO_PI - 1e-9 else -self.fov / 2.0

    @property
    def angles(self) -> np.ndarray:
        """Beam angles in the lidar frame [rad]."""
        return self.angle_min + np.arange(self.beams) * self.angular_step


class Lidar:
    """One lidar: true ranges by ray casting, then noise and dropouts (seeded, stateful)."""

    def __init__(self, config: LidarConfig) -> None:
        self.config = config
        self.rng = np.random.default_rng(config.seed)
        self._angles = config.angles

    def origin(self, pose: tuple[float, float, float]) -> tuple[float, float, float]:
        """The lidar's position (x, y) and heading [rad] on the map with the base at ``pose``."""
        cfg = self.config
        bx, by, bt = pose
        c, s = math.cos(bt), math.sin(bt)
        return bx + c * cfg.x - s * cfg.y, by + s * cfg.x + c * cfg.y, bt + cfg.yaw

    def rays(self, pose: tuple[float, float, float]) -> tuple[float, float, np.ndarray]:
        """The beams' origin (x, y) and world angles [rad] with the base at ``pose``."""
        lx, ly, heading = self.origin(pose)
        return lx, ly, self._angles + heading

    def true_ranges(self, scene: Scene, pose: tuple[float, float, float],
                    grid_distance: np.ndarray | None = None) -> np.ndarray:
        """Exact distances [m] (inf: nothing within range_max) with the base at ``pose``
        (x, y, theta in the map frame). ``grid_distance``: the map's part already cast
        (:meth:`LidarRig.scans` casts every lidar's rays in one call)."""
        cfg = self.config
        lx, ly, world = self.rays(pose)
        dist = grid_distance if grid_distance is not None else cast_grid(
            scene.mask, scene.grid, lx, ly, world, cfg.range_max, scene.grid_field).distance
        solids = solids_taller_than(scene.solids, cfg.z)
        if solids:
            dist = np.minimum(dist, cast_solids(solids, lx, ly, world))
        return np.where(dist <= cfg.range_max, dist, np.inf)

    def draw(self) -> Draws:
        """The random numbers of one scan (range noise, dropouts), in the order
        :meth:`measure` takes them: drawn ahead, a scan that is never cast still advances the
        generator as casting it would have (:meth:`LidarRig.draw`)."""
        n = self.config.beams
        normal = self.rng.standard_normal(n)
        return normal, self.rng.random(n) if self.config.dropout_prob > 0 else None

    def measure(self, true: np.ndarray, draws: Draws | None = None) -> np.ndarray:
        """REP-117 ranges (float32) from true distances: noise, limits, dropouts (``draws``:
        this scan's random numbers from :meth:`draw`; None: drawn now)."""
        cfg = self.config
        normal, uniform = draws if draws is not None else self.draw()
        finite = np.isfinite(true)
        sigma = cfg.range_sigma + cfg.range_sigma_per_m * np.where(finite, true, 0.0)
        noisy = true + sigma * normal
        out = np.where(finite, np.clip(noisy, cfg.range_min, cfg.range_max), np.inf)
        out = np.where(true < cfg.range_min, -np.inf, out)
        if uniform is not None:
            out = np.where(uniform < cfg.dropout_prob, np.nan, out)
        return out.astype(np.float32)

    def scan(self, scene: Scene, pose: tuple[float, float, float], stamp: float,
             grid_distance: np.ndarray | None = None, draws: Draws | None = None) -> LaserScan:
        cfg = self.config
        period = 1.0 / cfg.rate_hz
        return LaserScan(cfg.frame_id, stamp, cfg.angle_min,
                         cfg.angle_min + (cfg.beams - 1) * cfg.angular_step, cfg.angular_step,
                         period / cfg.beams, period, cfg.range_min, cfg.range_max,
                         self.measure(self.true_ranges(scene, pose, grid_distance), draws))


@dataclass(frozen=True)
class MergedScanConfig:
    """The fused /scan in base_link: ``beams`` bins from ``angle_min`` over ``fov`` [rad]."""

    frame_id: str = "base_link"
    beams: int = 720
    angle_min: float = -math.pi
    fov: float = TWO_PI

    def __post_init__(self) -> None:
        if isinstance(self.beams, bool) or not isinstance(self.beams, int) \
                or not 1 <= self.beams <= 100_000:
            raise ConfigError(f"scan.beams = {self.beams!r} is invalid; allowed: 1..100000")
        if not (math.isfinite(self.fov) and 0 < self.fov <= TWO_PI):
            raise ConfigError(f"scan.fov = {self.fov!r} is invalid; allowed: > 0 and <= 2 pi")
        if not (math.isfinite(self.angle_min) and -TWO_PI <= self.angle_min <= TWO_PI):
            raise ConfigError(f"scan.angle_min = {self.angle_min!r} is invalid; allowed: "
                              f"-2 pi .. 2 pi")
        if not self.frame_id:
            raise ConfigError("scan.frame_id must be non-empty")

    @property
    def full_circle(self) -> bool:
        return self.fov >= TWO_PI - 1e-9

    @property
    def increment(self) -> float:
        return self.fov / (self.beams if self.full_circle else max(self.beams - 1, 1))


@dataclass
class ScanMerger:
    """Fuses the lidars' scans into one LaserScan in base_link (nearest return per bin)."""

    lidars: Sequence[LidarConfig]
    merged: MergedScanConfig = field(default_factory=MergedScanConfig)

    def __post_init__(self) -> None:
        if not self.lidars:
            raise ConfigError("at least one lidar is needed for /scan")
        names = [lc.name for lc in self.lidars]
        if len(set(names)) != len(names):
            raise ConfigError(f"lidar names must be unique, got {names}")
        self._cached: _MergeConstants | None = None

    @property
    def rate_hz(self) -> float:
        """The merged scan comes at the slowest lidar's rate."""
        return min(lc.rate_hz for lc in self.lidars)

    @property
    def range_min(self) -> float:
        return min(lc.range_min for lc in self.lidars)

    @property
    def range_max(self) -> float:
        return max(lc.range_max + math.hypot(lc.x, lc.y) for lc in self.lidars)

    def merge(self, scans: Sequence[LaserScan], stamp: float) -> LaserScan:
        """Nearest valid return per merged beam. A beam with none is ``-inf`` if a lidar saw
        something too close in it, else ``+inf`` if a lidar looked through it without a return,
        else ``NaN`` (only dropouts, or no lidar covers it).

        Each beam's arithmetic is its own and the same for every scan but for its range: the
        per-beam constants (mount, direction cosines, the reach of a non-finite return) are
        computed once (:class:`_MergeConstants`), with the same numpy expressions, so the
        result is bit for bit what computing them per scan gave (tests/world/test_lidar_merge.py
        pins it against that). The per-return work is compiled (:mod:`scan_kernel`)."""
        key = tuple((s.ranges.size, s.angle_min, s.angle_increment) for s in scans)
        return self.merge_ranges(np.concatenate([scan.ranges for scan in scans]), key, stamp)

    def merge_ranges(self, ranges: np.ndarray, key: tuple[tuple[int, float, float], ...],
                     stamp: float) -> LaserScan:
        """:meth:`merge` of the lidars' ranges concatenated, ``key`` each scan's (size,
        angle_min, angle_increment)."""
        from lowerbase.world.scan_kernel import merge_bins, merge_points

        m = self.merged
        n = m.beams
        inc = m.increment
        if self._cached is None or self._cached.key != key:
            self._cached = _MergeConstants.build(self.lidars, key)
        k = self._cached
        px, py = np.empty(ranges.size), np.empty(ranges.size)
        merge_points(ranges, k.lx, k.ly, k.cos, k.sin, k.far, k.near, px, py)
        rel = np.arctan2(py, px) - m.angle_min  # numpy's arctan2 (see scan_kernel)
        out = np.empty(n, dtype=np.float32)
        merge_bins(ranges, px, py, rel, n, inc, m.full_circle, TWO_PI, out)
        period = 1.0 / self.rate_hz
        return LaserScan(m.frame_id, stamp, m.angle_min, m.angle_min + (n - 1) * inc, inc,
                         period / n, period, self.range_min, self.range_max, out)


@dataclass(frozen=True)
class _MergeConstants:
    """Per-beam constants of :meth:`ScanMerger.merge` for one set of scan beams (``key``: each
    scan's size, angle_min, angle_increment): the mounts, the beams' cosines and sines in
    base_link, the reach of a +inf / -inf return."""

    key: tuple[tuple[int, float, float], ...]
    lx: np.ndarray
    ly: np.ndarray
    cos: np.ndarray
    sin: np.ndarray
    far: np.ndarray
    near: np.ndarray

    @classmethod
    def build(cls, lidars: Sequence[LidarConfig], key: tuple[tuple[int, float, float], ...]
              ) -> _MergeConstants:
        sizes = [size for size, _, _ in key]

        def per_beam(values: list[float]) -> np.ndarray:
            return np.repeat(np.asarray(values, dtype=float), sizes)

        # as LaserScan.angles: angle_min + i * angle_increment, then the mount's yaw
        beam = np.concatenate([amin + np.arange(size) * inc + lc.yaw
                               for lc, (size, amin, inc) in zip(lidars, key, strict=True)])
        return cls(key, per_beam([lc.x for lc in lidars]), per_beam([lc.y for lc in lidars]),
                   np.cos(beam), np.sin(beam), per_beam([lc.range_max for lc in lidars]),
                   per_beam([lc.range_min for lc in lidars]))


class LidarRig:
    """The robot's lidars and their merger: ``scan()`` is one /scan message."""

    def __init__(self, lidars: Sequence[LidarConfig],
                 merged: MergedScanConfig | None = None) -> None:
        self.merger = ScanMerger(list(lidars), merged or MergedScanConfig())
        self.lidars = [Lidar(lc) for lc in lidars]
        # what every scan's rays share: beams per lidar, their angles in the lidar frames
        self._sizes = [lidar.config.beams for lidar in self.lidars]
        self._bounds = np.cumsum(self._sizes)[:-1]
        self._angles = np.concatenate([lidar._angles for lidar in self.lidars])
        self._u_max: tuple[float, np.ndarray] | None = None  #: (resolution, ranges [cells])
        #: each lidar scan's (size, angle_min, angle_increment), as LaserScan carries them
        self._key = tuple((lidar.config.beams, lidar.config.angle_min, lidar.config.angular_step)
                          for lidar in self.lidars)
        #: the last map cast: (grid, grid field, pose bits, distances, read-only)
        self._last_cast: tuple[OccupancyGrid, GridField, bytes, np.ndarray] | None = None

    @property
    def rate_hz(self) -> float:
        return self.merger.rate_hz

    def draw(self) -> list[Draws]:
        """Every lidar's random numbers for one scan (:meth:`Lidar.draw`)."""
        return [lidar.draw() for lidar in self.lidars]

    def _rays(self, scene: Scene, pose: tuple[float, float, float]) -> Rays:
        """Every lidar's rays in grid cells, as :func:`prepare_rays` makes them from the
        lidars' :meth:`Lidar.rays` (the same expressions, per lidar instead of per ray: each
        ray's origin, angle and range are the same floats), without its per-ray checks: a
        finite pose gives finite rays."""
        if not all(math.isfinite(v) for v in pose):
            raise WorldError("ray casting needs finite origins and angles and non-NaN ranges")
        grid = scene.grid
        if grid.origin[2] != 0.0:
            raise WorldError("sensors need a map whose origin yaw is 0; rotate the map image "
                             "instead")
        res = grid.resolution
        if self._u_max is None or self._u_max[0] != res:
            self._u_max = (res, np.repeat([lidar.config.range_max / res
                                           for lidar in self.lidars], self._sizes))
        gx, gy, yaw = [], [], []
        for lidar in self.lidars:
            cfg = lidar.config
            lx, ly, _ = lidar.origin(pose)
            gx.append((lx - grid.origin[0]) / res)
            gy.append((ly - grid.origin[1]) / res)
            yaw.append(pose[2] + cfg.yaw)
        ang = self._angles + np.repeat(yaw, self._sizes)
        return Rays(scene.grid_field, ang.shape, np.repeat(gx, self._sizes),
                    np.repeat(gy, self._sizes), np.cos(ang), np.sin(ang), self._u_max[1])

    def grid_distance(self, scene: Scene, pose: tuple[float, float, float]) -> np.ndarray:
        """Every lidar's rays cast on the map (:func:`cast_rays_prepared` of :meth:`_rays`),
        read-only. A robot standing still casts the same rays on the same grid again: with
        the same grid, grid field and pose (bit for bit) as the last cast, its distances are
        returned again (the caster is a pure function of those: the same floats in, out)."""
        grid, fld = scene.grid, scene.grid_field
        bits = struct.pack("<3d", *pose)
        last = self._last_cast
        if last is not None and last[0] is grid and last[1] is fld and last[2] == bits:
            return last[3]
        dist = cast_rays_prepared(grid, self._rays(scene, pose)).distance
        dist.flags.writeable = False
        self._last_cast = (grid, fld, bits, dist)
        return dist

    def scans(self, scene: Scene, pose: tuple[float, float, float],
              stamp: float, draws: Sequence[Draws] | None = None) -> list[LaserScan]:
        """Each lidar's own scan, in its own frame. The map is cast for all lidars' rays in one
        :func:`cast_grid` call (fewer, larger array operations; each ray's result is its own,
        bit for bit as cast alone: tests/world/test_lidar.py)."""
        parts = np.split(self.grid_distance(scene, pose), self._bounds)
        ds: Sequence[Draws | None] = draws if draws is not None else [None] * len(parts)
        return [lidar.scan(scene, pose, stamp, part, d)
                for lidar, part, d in zip(self.lidars, parts, ds, strict=True)]

    def scan(self, scene: Scene, pose: tuple[float, float, float], stamp: float,
             draws: Sequence[Draws] | None = None) -> LaserScan:
        """The merged scan in base_link (``draws``: its random numbers, :meth:`draw`): the
        merge of :meth:`scans`, each lidar's noise compiled (:func:`scan_kernel.measure`, the
        floats of :meth:`Lidar.measure`) into one array for the merge."""
        from lowerbase.world.scan_kernel import measure

        dist = self.grid_distance(scene, pose)
        ranges = np.empty(dist.size, dtype=np.float32)
        start = 0
        for i, (lidar, part) in enumerate(zip(self.lidars, np.split(dist, self._bounds),
                                              strict=True)):
            cfg = lidar.config
            normal, uniform = draws[i] if draws is not None else lidar.draw()
            measure(lidar.true_ranges(scene, pose, part), normal,
                    uniform if uniform is not None else normal, uniform is not None,
                    cfg.range_sigma, cfg.range_sigma_per_m, cfg.range_min, cfg.range_max,
                    cfg.dropout_prob, ranges[start:start + part.size])
            start += part.size
        return self.merger.merge_ranges(ranges, self._key, stamp)
