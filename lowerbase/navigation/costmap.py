"""move_base's global and local costmaps without ROS: :class:`LayeredCostmap`.

A costmap is costmap_2d's layered grid: the master grid is rebuilt from the static layer (the
map), max-combined with the obstacle layer (marked and cleared from /scan and the depth
camera's cloud_without_planes) and inflated around every LETHAL cell by the padded footprint's
inscribed radius. :func:`global_costmap` covers the whole map (static + inflation);
:func:`local_costmap` is a rolling window around the robot (obstacles + inflation, the map
optional). The services of move_base and the vendor map onto methods: set_footprint
(:meth:`LayeredCostmap.set_footprint`), /move_base/enable_costmaps (:meth:`~LayeredCostmap.enable`)
and /move_base/clear_costmaps (:meth:`~LayeredCostmap.clear`). Costs and layers: ``layers``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from lowerbase.errors import ConfigError, WorldError
from lowerbase.navigation.layers import (
    FREE_SPACE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    Costmap2D,
    InflationLayer,
    InflationParams,
    Observation,
    ObstacleLayer,
    StaticLayer,
    StaticParams,
    combine_max,
    footprint_at,
    footprint_radii,
    inflation_cost,
)
from lowerbase.world.camera import CameraConfig
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, DEFAULT_PADDING, Footprint, check_pose
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import LaserScan

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class SourceParams:
    """One observation source of the obstacle layer (costmap_2d's per-source parameters)."""

    obstacle_range: float = 2.5
    raytrace_range: float = 3.0
    min_obstacle_height: float = 0.0
    max_obstacle_height: float = 2.0
    inf_is_valid: bool = False
    marking: bool = True
    clearing: bool = True

    def __post_init__(self) -> None:
        for key in ("obstacle_range", "raytrace_range", "max_obstacle_height"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"observation source {key} = {v!r} is invalid; allowed: >= 0")
        if not (math.isfinite(self.min_obstacle_height)
                and self.min_obstacle_height <= self.max_obstacle_height):
            raise ConfigError(f"observation source min_obstacle_height = "
                              f"{self.min_obstacle_height!r} is invalid; allowed: finite and "
                              f"<= max_obstacle_height ({self.max_obstacle_height})")


@dataclass(frozen=True)
class CostmapParams:
    """The costmap's parameters, by costmap_2d's names. ``static_map``/``obstacles`` switch the
    layers; ``width``/``height``/``resolution`` size a rolling window (a global costmap takes the
    map's size and resolution). ``footprint_padding`` defaults to the seed's 0.1 m (costmap_2d:
    0.01)."""

    rolling_window: bool = False
    width: float = 10.0
    height: float = 10.0
    resolution: float = 0.05
    footprint: Footprint = DEFAULT_FOOTPRINT
    footprint_padding: float = DEFAULT_PADDING
    static_map: bool = True
    static: StaticParams = field(default_factory=StaticParams)
    obstacles: bool = False
    track_unknown_space: bool = False          # obstacle_layer
    max_obstacle_height: float = 2.0           # obstacle_layer
    footprint_clearing_enabled: bool = True    # obstacle_layer
    scan: SourceParams = field(default_factory=SourceParams)
    cloud: SourceParams = field(default_factory=SourceParams)
    inflation: InflationParams = field(default_factory=InflationParams)

    def __post_init__(self) -> None:
        for key in ("width", "height", "resolution"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 1000):
                raise ConfigError(f"costmap {key} = {v!r} is invalid; allowed: > 0 and <= 1000")
        if self.rolling_window and round(self.width / self.resolution) * round(
                self.height / self.resolution) > 25_000_000:
            raise ConfigError("a rolling window of more than 25 million cells: make it smaller "
                              "or coarser")
        if not (math.isfinite(self.footprint_padding) and self.footprint_padding >= 0):
            raise ConfigError(f"footprint_padding = {self.footprint_padding!r} is invalid; "
                              f"allowed: >= 0 m")


@dataclass
class CostmapStats:
    updates: int = 0
    observations: int = 0
    ignored_disabled: int = 0   # observations dropped while enable_costmaps is false


class LayeredCostmap:
    """costmap_2d's Costmap2DROS without ROS: layers, the master grid and its services.

    ``costs`` (uint8, row 0 at the lowest y), ``resolution`` and ``origin`` (x, y) describe
    the master grid; it is rebuilt lazily after anything changed.
    """

    def __init__(self, grid: OccupancyGrid | None, params: CostmapParams | None = None,
                 pose: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        p = params or CostmapParams()
        if not (p.static_map or p.obstacles):
            raise ConfigError("a costmap needs the static map, the obstacle layer or both")
        if (p.static_map or not p.rolling_window) and grid is None:
            raise ConfigError("this costmap needs a map (static_map, or a global costmap)")
        self.params = p
        self.static = StaticLayer(grid, p.static) if grid is not None and p.static_map else None
        self._ref = (grid.origin[0], grid.origin[1]) if grid is not None else (0.0, 0.0)
        self.pose = check_pose(pose)
        if p.rolling_window:
            w, h = round(p.width / p.resolution), round(p.height / p.resolution)
            self.map = Costmap2D(w, h, p.resolution, self._window_origin(self.pose, w, h,
                                                                          p.resolution))
        else:
            assert grid is not None
            self.map = Costmap2D(grid.width, grid.height, grid.resolution,
                                 (grid.origin[0], grid.origin[1]))
        self.map.default = NO_INFORMATION if (self.static is None and p.track_unknown_space) \
            else FREE_SPACE
        self.obstacle_layer = ObstacleLayer(self.map, p.track_unknown_space,
                                            p.max_obstacle_height) if p.obstacles else None
        self.inflation = InflationLayer(p.inflation)
        self.enabled = True
        self.stats = CostmapStats()
        self._set_footprint(p.footprint)
        self._dirty = True
        self._clear_footprint()

    # -- geometry -----------------------------------------------------------------------
    @property
    def resolution(self) -> float:
        return self.map.resolution

    @property
    def origin(self) -> tuple[float, float]:
        return self.map.origin

    @property
    def costs(self) -> np.ndarray:
        """The master grid (read-only view), rebuilt if anything changed."""
        if self._dirty:
            self._rebuild()
        return self._view

    def world_to_map(self, x: np.ndarray | float, y: np.ndarray | float
                     ) -> tuple[np.ndarray, np.ndarray]:
        return self.map.world_to_map(x, y)

    def map_to_world(self, col: np.ndarray | int, row: np.ndarray | int
                     ) -> tuple[np.ndarray, np.ndarray]:
        return self.map.map_to_world(col, row)

    def cost_at(self, x: float, y: float) -> int:
        """The cost of the cell under a map point; NO_INFORMATION outside the grid."""
        c, r = self.map.world_to_map(x, y)
        return int(self.costs[r, c]) if self.map.inside(c, r) else NO_INFORMATION

    def _window_origin(self, pose: Pose, w: int, h: int, res: float) -> tuple[float, float]:
        """The window's corner for a robot at ``pose``: centred, on the map's cell grid."""
        ox = self._ref[0] + math.floor((pose[0] - w * res / 2 - self._ref[0]) / res) * res
        oy = self._ref[1] + math.floor((pose[1] - h * res / 2 - self._ref[1]) / res) * res
        return ox, oy

    # -- footprint ----------------------------------------------------------------------
    def _set_footprint(self, footprint: Footprint) -> None:
        self.footprint = footprint
        self.padded = footprint.padded(self.params.footprint_padding)
        self.inscribed_radius, self.circumscribed_radius = footprint_radii(self.padded)

    def set_footprint(self, points: Sequence[Sequence[float]]) -> None:
        """/move_base/*_costmap/set_footprint: a new polygon (x, y[, z]) in base_link, padded by
        ``footprint_padding``; inflation follows. A bad polygon raises one :class:`WorldError`
        line and changes nothing."""
        try:
            pts = tuple((float(p[0]), float(p[1])) for p in points)
        except (TypeError, ValueError, IndexError):
            raise WorldError(f"set_footprint: a footprint is a list of (x, y) points, got "
                             f"{points!r}") from None
        try:
            footprint = Footprint(pts)
        except WorldError as exc:
            raise WorldError(f"set_footprint refused, footprint unchanged: {exc}") from None
        self._set_footprint(footprint)
        self._dirty = True

    @property
    def circumscribed_cost(self) -> int:
        """The cost at the circumscribed radius (costmap_2d's getCircumscribedCost)."""
        return int(inflation_cost(self.circumscribed_radius, self.inscribed_radius,
                                  self.params.inflation.cost_scaling_factor))

    def footprint_cost(self, pose: Sequence[float]) -> int:
        """The highest cost under the padded footprint at ``pose`` (its area and outline);
        LETHAL if any of it leaves the grid, as the planner treats the map's edge."""
        cols, rows, off = self.map.polygon_cells(footprint_at(self.padded, check_pose(pose)))
        if off:
            return LETHAL_OBSTACLE
        return int(self.costs[rows, cols].max()) if cols.size else FREE_SPACE

    # -- services -----------------------------------------------------------------------
    def enable(self, on: bool) -> tuple[bool, str]:
        """/move_base/enable_costmaps (SetBool): false leaves the obstacle layer out of the
        costs and ignores new observations (costmap_2d's layer ``enabled``); true brings its
        marks back and resumes updates. Answers (success, message)."""
        if self.obstacle_layer is None:
            return True, "this costmap has no obstacle layer: nothing to enable or disable"
        self.enabled = bool(on)
        self._dirty = True
        return True, "costmap updates enabled" if self.enabled else "costmap updates disabled"

    def clear(self) -> None:
        """/move_base/clear_costmaps: forget every marked obstacle (the static map stays)."""
        if self.obstacle_layer is not None:
            self.obstacle_layer.reset()
        self._dirty = True

    def clear_outside(self, x: float, y: float, size: float) -> int:
        """clear_costmap_recovery's reset: forget the marks outside the ``size`` x ``size`` m
        square centred on (x, y) [m] (the cells whose centre lies outside it); the number of
        marked cells forgotten."""
        return self._forget(x, y, size, inside=False)

    def clear_inside(self, x: float, y: float, size: float) -> int:
        """Forget the marks inside the ``size`` x ``size`` m square centred on (x, y) [m] (the
        cells whose centre lies inside it, edges included); the number of marked cells
        forgotten."""
        return self._forget(x, y, size, inside=True)

    def _forget(self, x: float, y: float, size: float, *, inside: bool) -> int:
        if self.obstacle_layer is None:
            return 0
        m = self.obstacle_layer.map
        cols = m.origin[0] + (np.arange(m.width) + 0.5) * m.resolution
        rows = m.origin[1] + (np.arange(m.height) + 0.5) * m.resolution
        within = (np.abs(rows - y)[:, None] <= 0.5 * size) & \
            (np.abs(cols - x)[None, :] <= 0.5 * size)
        forget = (within if inside else ~within) & (m.data != m.default)
        m.data[forget] = m.default
        self._dirty = True
        return int(forget.sum())

    # -- updates ------------------------------------------------------------------------
    def update(self, pose: Sequence[float], scan: LaserScan | None = None,
               cloud: tuple[np.ndarray, Sequence[float]] | None = None) -> None:
        """One update cycle at the robot's map ``pose``: move the rolling window, then clear
        and mark from the merged /scan (base_link) and a cloud ((n, 3) points in base_link,
        the sensor's origin in base_link), see :func:`camera_cloud`."""
        checked = check_pose(pose)
        obs: list[Observation] = []
        if scan is not None:
            obs.append(scan_observation(scan, checked, self.params.scan))
        if cloud is not None:
            obs.append(cloud_observation(cloud[0], cloud[1], checked, self.params.cloud))
        self.update_observations(checked, obs)

    def update_observations(self, pose: Sequence[float], observations: Sequence[Observation]
                            ) -> None:
        """As :meth:`update` with observations already in the map frame."""
        self.pose = check_pose(pose)
        self.stats.updates += 1
        if self.params.rolling_window:
            origin = self._window_origin(self.pose, self.map.width, self.map.height,
                                         self.map.resolution)
            self.map.shift_to(origin)
            if self.obstacle_layer is not None:
                self.obstacle_layer.map.shift_to(origin)
        if self.obstacle_layer is not None and observations:
            if self.enabled:
                self.obstacle_layer.update(list(observations))
                self.stats.observations += len(observations)
            else:
                self.stats.ignored_disabled += len(observations)
        self._clear_footprint()
        self._dirty = True

    def _clear_footprint(self) -> None:
        """footprint_clearing_enabled: the cells under the robot hold no obstacle."""
        if self.obstacle_layer is None or not self.params.footprint_clearing_enabled \
                or not self.enabled:
            return
        cols, rows, _ = self.map.polygon_cells(footprint_at(self.padded, self.pose))
        self.obstacle_layer.clear_cells(cols, rows)

    def _rebuild(self) -> None:
        m = self.map
        if self.static is not None:
            m.data = self.static.window(m).copy()
        else:
            m.reset()
        if self.obstacle_layer is not None and self.enabled:
            combine_max(m.data, self.obstacle_layer.map.data)
        self.inflation.apply(m.data, m.resolution, self.inscribed_radius)
        self._view = m.data.view()
        self._view.flags.writeable = False
        self._dirty = False


# ---------------------------------------------------------------------------- observations

def _to_map(points: np.ndarray, pose: Pose) -> np.ndarray:
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty_like(points, dtype=float)
    out[:, 0] = x + c * points[:, 0] - s * points[:, 1]
    out[:, 1] = y + s * points[:, 0] + c * points[:, 1]
    out[:, 2] = points[:, 2]
    return out


def _observation(points_base: np.ndarray, origin_base: Sequence[float], pose: Pose,
                 src: SourceParams) -> Observation:
    o = _to_map(np.asarray(origin_base, float).reshape(1, 3), pose)[0]
    return Observation((float(o[0]), float(o[1]), float(o[2])), _to_map(points_base, pose),
                       src.obstacle_range, src.raytrace_range, src.min_obstacle_height,
                       src.max_obstacle_height, src.marking, src.clearing)


def scan_observation(scan: LaserScan, pose: Pose, src: SourceParams) -> Observation:
    """A LaserScan in base_link as an observation at the robot's ``pose``, as laser_geometry's
    projectLaser: returns with range_min <= r < range_max; +inf becomes range_max - 1e-4
    (clearing only, beyond obstacle_range) when ``inf_is_valid``; -inf and NaN are dropped.
    Compiled (:func:`~lowerbase.navigation.kernels.scan_points`): the numpy expressions it
    replaced, in their order, so the same points bit for bit."""
    from lowerbase.navigation.kernels import scan_points

    ranges = np.asarray(scan.ranges)
    if ranges.dtype not in (np.float32, np.float64) or ranges.ndim != 1:
        ranges = np.asarray(ranges, float).ravel()
    cos, sin = _beam_directions(scan.angle_min, scan.angle_increment, ranges.size)
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    pts = np.empty((ranges.size, 3))
    n = scan_points(ranges, cos, sin, bool(src.inf_is_valid), float(scan.range_min),
                    float(scan.range_max), float(x), float(y), c, s, pts)
    # the sensor at base_link's origin: _to_map of (0, 0, 0), in the same floats
    origin = (x + c * 0.0 - s * 0.0, y + s * 0.0 + c * 0.0, 0.0)
    return Observation((float(origin[0]), float(origin[1]), float(origin[2])), pts[:n],
                       src.obstacle_range, src.raytrace_range, src.min_obstacle_height,
                       src.max_obstacle_height, src.marking, src.clearing)


#: the last scan geometry's beam cosines and sines: ((angle_min, angle_increment, size), cos, sin)
_DIRECTIONS: list[tuple[tuple[float, float, int], np.ndarray, np.ndarray]] = []


def _beam_directions(angle_min: float, increment: float, size: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of a LaserScan's beam angles (:attr:`LaserScan.angles`), computed once per
    scan geometry: numpy's cos and sin are elementwise, so ``cos(angles)[ok]`` is, bit for bit,
    the ``cos(angles[ok])`` computed per scan before (tests/navigation/test_mark_points.py)."""
    key = (float(angle_min), float(increment), int(size))
    for k, cos, sin in _DIRECTIONS:
        if k == key:
            return cos, sin
    angles = angle_min + np.arange(size) * increment
    cos, sin = np.cos(angles), np.sin(angles)
    cos.flags.writeable = sin.flags.writeable = False
    _DIRECTIONS[:] = [(key, cos, sin)]
    return cos, sin


def cloud_observation(points_base: np.ndarray, origin_base: Sequence[float], pose: Pose,
                      src: SourceParams) -> Observation:
    """A point cloud (n, 3) in base_link from a sensor at ``origin_base``; NaN points dropped."""
    p = np.asarray(points_base, float).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if len(origin_base) != 3 or not all(math.isfinite(float(v)) for v in origin_base):
        raise WorldError(f"a cloud's sensor origin is finite (x, y, z), got {origin_base!r}")
    return _observation(p, origin_base, pose, src)


def camera_cloud(points_optical: np.ndarray, camera: CameraConfig
                 ) -> tuple[np.ndarray, tuple[float, float, float]]:
    """cloud_without_planes (optical frame) as (points in base_link, the camera's origin)."""
    p = np.asarray(points_optical, float).reshape(-1, 3) @ camera.optical_to_base().T
    origin = (camera.x, camera.y, camera.z)
    return p + np.asarray(origin), origin


# ---------------------------------------------------------------------------- move_base's two

def global_costmap(grid: OccupancyGrid, params: CostmapParams | None = None) -> LayeredCostmap:
    """The global costmap: the whole map, static layer + inflation (obstacles if asked)."""
    return LayeredCostmap(grid, replace(params or CostmapParams(), rolling_window=False,
                                        static_map=True))


def local_costmap(grid: OccupancyGrid | None, pose: Sequence[float],
                  params: CostmapParams | None = None) -> LayeredCostmap:
    """The local costmap: a rolling window (default 5 x 5 m) around ``pose`` with the obstacle
    layer and inflation; the static map only if ``params.static_map``."""
    p = params or CostmapParams(width=5.0, height=5.0, static_map=False)
    return LayeredCostmap(grid, replace(p, rolling_window=True, obstacles=True), pose)
