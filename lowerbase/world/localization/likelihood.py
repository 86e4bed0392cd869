"""amcl's likelihood-field laser model, scored for every particle at once.

The field is the distance from each cell to the nearest occupied cell (scipy's exact Euclidean
distance transform of the occupied mask), capped at ``laser_likelihood_max_dist`` as amcl's
``map_update_cspace`` caps it; a beam end outside the map sees that cap. A beam ending ``d``
from the nearest obstacle has ``pz = z_hit exp(-d^2 / 2 sigma_hit^2) + z_rand / range_max``.

Two ways to combine the beams of one particle, as amcl's two likelihood-field models:

- ``likelihood_field`` (amcl's default): ``p = 1 + sum(pz^3)``, amcl's heuristic that keeps
  one bad beam from vetoing a pose (robust, but a broad posterior);
- ``likelihood_field_prob``: ``log p = sum(log pz)``, the beams' product (sharper, and
  over-confident when beams are correlated). With amcl's beam skipping (``do_beamskip``, for
  a converged filter) the beams that most particles see off the map's obstacles (an unmapped
  crate or person) are left out.

Beams at or beyond ``range_max`` (no return), under ``range_min`` and NaN are skipped; of the
rest, ``laser_max_beams`` evenly spaced ones are used (amcl's subsampling step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.ndimage import distance_transform_edt

from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.localization.params import AmclParams


class ScanLike(Protocol):
    """What a sensor_msgs/LaserScan carries that the model needs (its field names)."""

    @property
    def ranges(self) -> np.ndarray: ...
    @property
    def angle_min(self) -> float: ...
    @property
    def angle_increment(self) -> float: ...
    @property
    def range_min(self) -> float: ...
    @property
    def range_max(self) -> float: ...


@dataclass(frozen=True)
class Beams:
    """The used beams of one scan: end points in the base frame and the range limit used."""

    end_xy: np.ndarray   #: (M, 2) [m], base_link frame
    total: int           #: beams in the scan
    range_max: float


class LikelihoodField:
    """The field of one map; ``score`` weighs particles against a scan's beams."""

    def __init__(self, grid: OccupancyGrid, params: AmclParams) -> None:
        self.grid = grid
        self.params = params
        self.model_type = params.laser_model_type
        occupied = grid.occupied()
        max_d = params.laser_likelihood_max_dist
        if occupied.any():
            dist = distance_transform_edt(~occupied) * grid.resolution
        else:
            dist = np.full(occupied.shape, max_d)
        #: distance to the nearest obstacle [m], capped, flattened (float32: half the memory)
        self.dist = np.minimum(dist, max_d).astype(np.float32).ravel()
        s = params.laser_sigma_hit
        #: z_hit part of pz per cell (z_rand / range_max is added per scan)
        self.hit = (params.laser_z_hit * np.exp(-(self.dist.astype(np.float64) ** 2)
                                                / (2 * s * s))).astype(np.float32)
        self.hit_outside = float(params.laser_z_hit * math.exp(-(max_d ** 2) / (2 * s * s)))
        #: flat indices of known-free cells (global initialisation, recovery particles)
        self.free_cells = np.flatnonzero(grid.data.ravel() == 0)

    # -- beams ---------------------------------------------------------------------------------
    def beams(self, scan: ScanLike, laser_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
              ) -> Beams:
        """The scan's usable beams, subsampled to ``laser_max_beams``, as base-frame end points."""
        p = self.params
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        n = ranges.size
        r_max = p.laser_max_range if p.laser_max_range > 0 else float(scan.range_max)
        r_min = p.laser_min_range if p.laser_min_range >= 0 else float(scan.range_min)
        angles = scan.angle_min + scan.angle_increment * np.arange(n)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(ranges) & (ranges < r_max) & (ranges >= r_min)
        idx = np.flatnonzero(ok)
        if idx.size > p.laser_max_beams:
            idx = idx[np.round(np.linspace(0, idx.size - 1, p.laser_max_beams)).astype(np.int64)]
        r, a = ranges[idx], angles[idx] + laser_pose[2]
        end = np.column_stack((laser_pose[0] + r * np.cos(a), laser_pose[1] + r * np.sin(a)))
        return Beams(end, n, r_max)

    # -- lookups -------------------------------------------------------------------------------
    def _cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        col, row = self.grid.world_to_cell(x, y)
        inside = self.grid.inside(col, row)
        flat = np.where(inside, row * self.grid.width + col, 0)
        return flat, inside

    def _ends(self, poses: np.ndarray, beams: Beams) -> tuple[np.ndarray, np.ndarray]:
        c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
        bx, by = beams.end_xy[:, 0], beams.end_xy[:, 1]
        return poses[:, 0:1] + c * bx - s * by, poses[:, 1:2] + s * bx + c * by

    def gather(self, poses: np.ndarray, beams: Beams
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per particle and beam: the end's flat cell index (0 off the map), inside the map,
        its float32 z_hit term and ``pz`` (float64): compiled (:mod:`likelihood_kernel`),
        the floats of :meth:`gather_numpy`."""
        from lowerbase.world.localization.likelihood_kernel import gather

        n, m = poses.shape[0], beams.end_xy.shape[0]
        c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])  # as _ends takes them
        flat, inside = np.empty((n, m), np.int64), np.empty((n, m), bool)
        hit, pz = np.empty((n, m), np.float32), np.empty((n, m))
        ox, oy, _ = self.grid.origin
        gather(np.ascontiguousarray(poses[:, 0]), np.ascontiguousarray(poses[:, 1]),
               c[:, 0], s[:, 0], np.ascontiguousarray(beams.end_xy[:, 0]),
               np.ascontiguousarray(beams.end_xy[:, 1]), float(ox), float(oy),
               float(self.grid.resolution), int(self.grid.width), int(self.grid.height),
               self.hit, np.float32(self.hit_outside),
               self.params.laser_z_rand / beams.range_max, flat, inside, hit, pz)
        return flat, inside, hit, pz

    def gather_numpy(self, poses: np.ndarray, beams: Beams
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`gather` in numpy, as :meth:`score` computed it before (the reference)."""
        x, y = self._ends(poses, beams)
        flat, inside = self._cells(x, y)
        hit = np.where(inside, self.hit[flat], self.hit_outside)
        pz = hit.astype(np.float64) + self.params.laser_z_rand / beams.range_max
        return flat, inside, hit, pz

    def distances(self, pose: np.ndarray, beams: Beams) -> np.ndarray:
        """Distance [m] of each beam end to the nearest obstacle, seen from ``pose``."""
        x, y = self._ends(np.asarray(pose, dtype=np.float64).reshape(1, 3), beams)
        flat, inside = self._cells(x[0], y[0])
        return np.where(inside, self.dist[flat], self.params.laser_likelihood_max_dist)

    def score(self, poses: np.ndarray, beams: Beams, skip: bool = False
              ) -> tuple[np.ndarray, bool, int]:
        """Per-particle log-likelihood of the beams; True when it is amcl's cube-sum ``log p``;
        the number of beams weighed.

        Returns ``log p`` for both models (``log(1 + sum pz^3)`` or ``sum log pz``), so the
        filter works in the log domain without underflow. ``skip``: amcl's beam skipping
        (``likelihood_field_prob`` only, see AmclParams.do_beamskip).
        """
        m = beams.end_xy.shape[0]
        if m == 0:
            return np.zeros(poses.shape[0]), self.model_type == "likelihood_field", 0
        flat, inside, hit, pz = self.gather(poses, beams)
        k = self.params.laser_likelihood_exponent
        if self.model_type == "likelihood_field":
            return k * np.log1p(np.sum(pz * pz * pz, axis=1)), True, m
        log_pz = np.log(pz)
        if skip:
            used = self._agreed(flat, inside, hit)
            if used is not None:
                return k * np.sum(log_pz[:, used], axis=1), False, int(used.sum())
        return k * np.sum(log_pz, axis=1), False, m

    def _agreed(self, flat: np.ndarray, inside: np.ndarray, hit: np.ndarray
                ) -> np.ndarray | None:
        """amcl's beam skipping: the beams (mask) whose end more than ``beam_skip_threshold`` of
        the particles see within ``beam_skip_distance`` of a mapped obstacle (off the map: not
        near); None (use all) when ``beam_skip_error_threshold`` of them or more would go."""
        p = self.params
        if p.laser_z_hit > 0:  # hit is monotone in the distance: compare it, not gather again
            s = p.laser_sigma_hit
            near = inside & (hit > np.float32(
                p.laser_z_hit * math.exp(-(p.beam_skip_distance ** 2) / (2 * s * s))))
        else:
            near = inside & (self.dist[flat] < p.beam_skip_distance)
        used = np.count_nonzero(near, axis=0) > p.beam_skip_threshold * near.shape[0]
        skipped = used.size - int(used.sum())
        if skipped == 0 or skipped >= used.size * p.beam_skip_error_threshold:
            return None
        return used

    # -- free space ----------------------------------------------------------------------------
    def is_free(self, x: float, y: float) -> bool:
        col, row = self.grid.world_to_cell(x, y)
        if not bool(self.grid.inside(col, row)):
            return False
        return bool(self.grid.data[int(row), int(col)] == 0)

    def uniform_poses(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` poses uniform over the known-free cells, any heading (amcl's pose generator)."""
        cells = self.free_cells[rng.integers(0, self.free_cells.size, n)]
        row, col = np.divmod(cells, self.grid.width)
        ox, oy, _ = self.grid.origin
        res = self.grid.resolution
        out = np.empty((n, 3))
        out[:, 0] = ox + (col + rng.random(n)) * res
        out[:, 1] = oy + (row + rng.random(n)) * res
        out[:, 2] = rng.uniform(-math.pi, math.pi, n)
        return out
