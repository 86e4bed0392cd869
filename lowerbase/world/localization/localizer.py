"""The chassis' positioning module, ROS-free: amcl's particle filter behind the vendor's controls.

Feed it ``update(odom_pose, scan)`` (the /odom pose at the scan's time, and the scan merged in
base_link); it answers a :class:`PoseEstimate` (what /amcl_pose, movebase_pose2d and the
map -> odom transform carry) on each filter update, ``None`` otherwise. As amcl, the filter
updates only after ``update_min_d`` of travel or ``update_min_a`` of rotation (and on the
first scan after an initialisation); between updates :meth:`Localizer.pose_from_odom` gives the
map pose from the last map -> odom transform.

Controls (each refuses bad input with one :class:`~lowerbase.errors.WorldError` line and keeps
the old state): :meth:`start` (/start_localization, std_srvs/SetBool), :meth:`initial_pose`
(/initialpose), :meth:`set_map` (set_map, nav_msgs/SetMap), :meth:`global_localization`, and
:meth:`set_ground_truth` (publish the true pose instead of the filter's).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from lowerbase.clock import Clock
from lowerbase.errors import WorldError
from lowerbase.text import point
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.localization.likelihood import Beams, LikelihoodField, ScanLike
from lowerbase.world.localization.motion import sample_diff
from lowerbase.world.localization.params import AmclParams
from lowerbase.world.localization.particles import ParticleSet
from lowerbase.world.localization.poses import Pose2D, compose, inverse, is_finite_pose, wrap
from lowerbase.world.localization.slipcheck import scaled_odom, slip_fraction

log = logging.getLogger(__name__)

#: indices of x, y, yaw in a row-major 6x6 ROS covariance (x, y, z, roll, pitch, yaw)
_ROS_INDEX = (0, 1, 5)


@dataclass(frozen=True)
class PoseEstimate:
    """One localization result (map frame)."""

    stamp: float                 #: clock time [s]
    pose: Pose2D                 #: base_link in map
    cov: tuple[tuple[float, float, float], ...]  #: 3x3 (x, y, yaw) [m^2, m rad, rad^2]
    map_to_odom: Pose2D          #: the map -> odom transform
    source: str                  #: "filter" or "truth"
    sigma_xy: float              #: sqrt of the largest position eigenvalue [m]
    sigma_yaw: float             #: heading standard deviation [rad]
    fit: float                   #: fraction of used beams ending within fit_tolerance (NaN: none)
    lost: bool                   #: see AmclParams.lost_* (always False for "truth")
    particles: int

    @property
    def covariance(self) -> tuple[float, ...]:
        """The 36-element row-major 6x6 covariance of geometry_msgs/PoseWithCovariance."""
        out = [0.0] * 36
        for i, ri in enumerate(_ROS_INDEX):
            for j, rj in enumerate(_ROS_INDEX):
                out[6 * ri + rj] = self.cov[i][j]
        return tuple(out)

    @property
    def converged(self) -> bool:
        return not self.lost


@dataclass
class LocalizerStats:
    filter_updates: int = 0
    skipped_small_motion: int = 0
    dropped_stopped: int = 0
    dropped_bad_input: int = 0
    resamples: int = 0
    injected: int = 0
    slips: int = 0  #: updates whose odometry step the slip check cut (wheel slip)


def cov3_from(cov: Sequence[float] | np.ndarray | None, default: tuple[float, float, float]
              ) -> np.ndarray:
    """A 3x3 (x, y, yaw) covariance from 3x3, a ROS 36-element 6x6, or None (diagonal default)."""
    if cov is None:
        return np.diag(default)
    try:
        arr = np.asarray(cov, dtype=np.float64)
    except (TypeError, ValueError):
        raise WorldError("initial pose covariance must be numbers (3x3 or 36 values)") from None
    if arr.size == 36:
        arr = arr.reshape(6, 6)[np.ix_(_ROS_INDEX, _ROS_INDEX)]
    elif arr.size == 9:
        arr = arr.reshape(3, 3)
    else:
        raise WorldError(f"initial pose covariance must have 9 or 36 values, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise WorldError("initial pose covariance must be finite")
    if not np.allclose(arr, arr.T, atol=1e-9):
        raise WorldError("initial pose covariance must be symmetric")
    if np.linalg.eigvalsh(arr).min() < -1e-12:
        raise WorldError("initial pose covariance must be positive semi-definite")
    return arr


class Localizer:
    """amcl on an injected clock. See the module docstring for the data flow and controls."""

    def __init__(self, grid: OccupancyGrid, params: AmclParams | None = None, *, clock: Clock,
                 seed: int = 0, laser_pose: Pose2D = (0.0, 0.0, 0.0),
                 initial_pose: Pose2D | None = None,
                 initial_cov: Sequence[float] | np.ndarray | None = None,
                 global_init: bool = False,
                 truth: Callable[[], Pose2D] | None = None, ground_truth: bool = False,
                 running: bool = True) -> None:
        self.params = params or AmclParams()
        self.clock = clock
        self.laser_pose = laser_pose
        self._truth = truth
        if ground_truth and truth is None:
            raise WorldError("ground-truth localization needs a truth source")
        self.ground_truth = ground_truth
        self.running = running
        self.stats = LocalizerStats()
        self._rng = np.random.default_rng(seed)
        self._field = self._make_field(grid)
        self._set = ParticleSet(self.params, self._rng)
        self._odom_ref: Pose2D | None = None
        self._force = True
        self.last: PoseEstimate | None = None
        if global_init:
            self._set.init_uniform(self._field)
        else:
            p = self.params
            start = initial_pose or (p.initial_pose_x, p.initial_pose_y, p.initial_pose_a)
            self._check_pose(self._field, start, "initial pose")
            self._set.init_gaussian(start, cov3_from(initial_cov, p.initial_cov))

    # -- state ---------------------------------------------------------------------------------
    @property
    def grid(self) -> OccupancyGrid:
        return self._field.grid

    @property
    def particles(self) -> np.ndarray:
        """The particle poses (read-only view)."""
        view = self._set.poses.view()
        view.flags.writeable = False
        return view

    @property
    def map_to_odom(self) -> Pose2D | None:
        return self.last.map_to_odom if self.last else None

    def pose_from_odom(self, odom: Pose2D) -> Pose2D | None:
        """The map pose of base_link at ``odom`` through the last map -> odom transform."""
        return compose(self.last.map_to_odom, odom) if self.last else None

    # -- controls ------------------------------------------------------------------------------
    def start(self, on: bool) -> tuple[bool, str]:
        """/start_localization (std_srvs/SetBool): (success, message). Restarting resumes
        from the particles it had, moved by the odometry since (with its noise)."""
        if on == self.running:
            return True, f"localization already {'running' if on else 'stopped'}"
        self.running = on
        self._force = on
        return True, f"localization {'started' if on else 'stopped'}"

    def initial_pose(self, pose: Pose2D, cov: Sequence[float] | np.ndarray | None = None) -> None:
        """/initialpose: particles drawn from N(pose, cov); the next scan updates at once."""
        self._check_pose(self._field, pose, "initial pose")
        cov3 = cov3_from(cov, self.params.initial_cov)
        self._set.init_gaussian(tuple(float(v) for v in pose), cov3)  # type: ignore[arg-type]
        self._force = True

    def global_localization(self) -> None:
        """amcl's /global_localization: particles uniform over the free space."""
        self._set.init_uniform(self._field)
        self._force = True

    def set_map(self, grid: OccupancyGrid, pose: Pose2D,
                cov: Sequence[float] | np.ndarray | None = None) -> None:
        """set_map (nav_msgs/SetMap): a new map and the robot's pose on it, all or nothing."""
        new_field = self._make_field(grid)
        self._check_pose(new_field, pose, "initial pose")
        cov3 = cov3_from(cov, self.params.initial_cov)
        self._field = new_field
        self._set.init_gaussian(tuple(float(v) for v in pose), cov3)  # type: ignore[arg-type]
        self.last = None
        self._force = True

    def set_ground_truth(self, on: bool) -> None:
        if on and self._truth is None:
            raise WorldError("ground-truth localization needs a truth source")
        self.ground_truth = on
        self._force = True

    # -- data ----------------------------------------------------------------------------------
    def update(self, odom: Pose2D, scan: ScanLike, truth: Pose2D | None = None
               ) -> PoseEstimate | None:
        """One scan with the odometry pose at its time; an estimate when the filter updated.

        ``truth``: the true pose at the scan's time, for the ground-truth mode (default: the
        truth source now; a scan handled later than its stamp pairs it with later motion)."""
        if not self.running:
            self.stats.dropped_stopped += 1
            return None
        if not is_finite_pose(odom):
            self._drop(f"odometry pose {odom!r} is not three finite numbers")
            return None
        odom = (float(odom[0]), float(odom[1]), float(odom[2]))
        ref = self._odom_ref
        if not self.ground_truth and ref is not None and not self._force:
            moved = math.hypot(odom[0] - ref[0], odom[1] - ref[1])
            turned = abs(float(wrap(odom[2] - ref[2])))
            if moved < self.params.update_min_d and turned < self.params.update_min_a:
                self.stats.skipped_small_motion += 1
                return None  # the scan is not read (a lazy one is never cast)
        problem = _bad_scan(scan)
        if problem:
            self._drop(problem)
            return None
        if self.ground_truth:
            return self._truth_update(odom, scan, truth)
        p = self.params
        beams = self._field.beams(scan, self.laser_pose)
        if ref is not None:
            moved_to = odom
            if p.slip_check and self.last is not None and self.last.source == "filter" \
                    and not self._force and self._set.converged():  # one pose to move
                frac = slip_fraction(self._field, beams, self.last.pose, ref, odom,
                                     p.slip_min_log_ratio)
                if frac < 1.0:
                    self.stats.slips += 1
                    moved_to = scaled_odom(ref, odom, frac)
            sample_diff(self._set.poses, ref, moved_to,
                        (p.odom_alpha1, p.odom_alpha2, p.odom_alpha3, p.odom_alpha4), self._rng,
                        noise_of=odom)
        skip = p.do_beamskip and self._set.converged()
        log_p, cube, used = self._field.score(self._set.poses, beams, skip)
        self._set.correct(log_p, cube, used)
        pose, cov, _ = self._set.estimate()
        est = self._estimate(pose, cov, odom, beams, "filter")
        if self._set.resample_due():
            self.stats.injected += self._set.resample(self._field)
            self.stats.resamples += 1
        self._odom_ref = odom
        self._force = False
        self.stats.filter_updates += 1
        return est

    # -- internals -----------------------------------------------------------------------------
    def _drop(self, problem: str) -> None:
        self.stats.dropped_bad_input += 1
        log.warning("localization: scan dropped (%s); %d dropped so far", problem,
                    self.stats.dropped_bad_input)

    def _truth_update(self, odom: Pose2D, scan: ScanLike, truth: Pose2D | None
                      ) -> PoseEstimate | None:
        assert self._truth is not None
        if truth is None:
            truth = self._truth()
        if not is_finite_pose(truth):
            self.stats.dropped_bad_input += 1
            log.warning("localization: the truth source gave %r; update dropped", truth)
            return None
        truth = (float(truth[0]), float(truth[1]), float(wrap(truth[2])))
        beams = self._field.beams(scan, self.laser_pose)
        self._odom_ref = odom
        return self._estimate(truth, np.zeros((3, 3)), odom, beams, "truth")

    def _estimate(self, pose: Pose2D, cov: np.ndarray, odom: Pose2D, beams: Beams,
                  source: str) -> PoseEstimate:
        p = self.params
        sigma_xy = math.sqrt(max(0.0, float(np.linalg.eigvalsh(cov[:2, :2]).max())))
        sigma_yaw = math.sqrt(max(0.0, float(cov[2, 2])))
        if beams.end_xy.shape[0]:
            dist = self._field.distances(np.asarray(pose), beams)
            fit = float(np.mean(dist <= p.fit_tolerance))
        else:
            fit = float("nan")
        lost = source == "filter" and (sigma_xy > p.lost_sigma_xy or sigma_yaw > p.lost_sigma_yaw
                                       or fit < p.lost_min_fit)
        est = PoseEstimate(
            stamp=self.clock.now(), pose=pose,
            cov=tuple(tuple(float(v) for v in row) for row in cov),  # type: ignore[misc]
            map_to_odom=compose(pose, inverse(odom)), source=source, sigma_xy=sigma_xy,
            sigma_yaw=sigma_yaw, fit=fit, lost=lost, particles=self._set.count)
        self.last = est
        return est

    def _make_field(self, grid: OccupancyGrid) -> LikelihoodField:
        if not isinstance(grid, OccupancyGrid):
            raise WorldError(f"a map must be an OccupancyGrid, got {type(grid).__name__}")
        new_field = LikelihoodField(grid, self.params)
        if new_field.free_cells.size == 0:
            raise WorldError("the map has no free cells: nowhere to localize")
        return new_field

    @staticmethod
    def _check_pose(fld: LikelihoodField, pose: object, what: str) -> None:
        if not is_finite_pose(pose):
            raise WorldError(f"{what} must be three finite numbers (x, y, yaw), got {pose!r}")
        x, y = float(pose[0]), float(pose[1])  # type: ignore[index]
        if not fld.grid.contains(x, y):  # before the cell arithmetic: 1e300 / res overflows
            x0, y0, x1, y1 = fld.grid.extent
            raise WorldError(f"{what} {point(x, y, decimals=3)} is outside the map "
                             f"(x {x0:g}..{x1:g}, y {y0:g}..{y1:g} m)")
        if not fld.is_free(x, y):
            raise WorldError(f"{what} {point(x, y, decimals=3)} is not in free space on the map "
                             "(an occupied or unknown cell): place the robot in free space")


def _bad_scan(scan: ScanLike) -> str:
    try:
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        inc, rmax = float(scan.angle_increment), float(scan.range_max)
        amin, rmin = float(scan.angle_min), float(scan.range_min)
    except (AttributeError, TypeError, ValueError) as exc:
        return f"not a laser scan ({exc})"
    if ranges.ndim != 1 or ranges.size == 0:
        return f"scan ranges must be a non-empty 1D array, got shape {ranges.shape}"
    if not (math.isfinite(inc) and inc != 0 and math.isfinite(amin)):
        return f"scan angles must be finite with a non-zero increment (angle_increment={inc})"
    if not (math.isfinite(rmax) and rmax > 0 and math.isfinite(rmin) and rmin < rmax):
        return f"scan range limits must be finite with range_min < range_max ({rmin}, {rmax})"
    return ""
