"""The particle set: weights in the log domain, augmented MCL, KLD-sampling, cluster estimate.

- Correction: ``w_i <- w_i p_i`` (normalised; ``log p`` from the laser model, so no
  underflow). The scan's *fit* is the posterior-weighted mean of each particle's per-beam
  likelihood; ``w_slow`` and ``w_fast`` are its slow and fast exponential averages
  (``recovery_alpha_slow`` / ``_fast``), started at the first fit as amcl starts them.
  (amcl averages the prior-weighted total instead: that counts its own injected particles
  as a bad fit and keeps injecting; the posterior-weighted fit does not.)
- Resampling, low-variance (systematic), when ``N_eff < resample_ess N`` or when recovery is
  due: a fraction ``w_diff = max(0, 1 - w_fast / w_slow)`` of the new particles (when over
  ``recovery_min_w_diff``) is drawn uniformly over the map's free space (augmented MCL,
  Probabilistic Robotics table 8.3: w_slow/w_fast are not reset after an injection).
- KLD-sampling (Fox 2003, as amcl's ``pf_update_resample``): new particles are taken, in
  random order, until their count exceeds amcl's ``pf_resample_limit(k)`` for the ``k``
  histogram bins (``kld_bin_xy`` x ``kld_bin_xy`` x ``kld_bin_yaw``) they occupy, within
  [min_particles, max_particles]. ``kld_sampling=False``: always max_particles.
- Estimate: particles are clustered by connected histogram bins (amcl's ``pf_cluster_stats``,
  3x3x3 neighbourhood, heading wrapping round); the estimate is the weighted mean of the
  heaviest cluster (circular mean for the heading); its covariance is the posterior mean of
  ``(x - x_hat)(x - x_hat)^T`` over *all* particles (heading differences wrapped), so a second
  mode or a spread cloud shows in it, plus the regularised particle filter's kernel
  ``h^2 C_prior`` (Musso et al. 2001: ``h = (4 / (d + 2))^(1/(d+4)) N^(-1/(d+4))``, d = 3,
  ``C_prior`` the cloud's covariance before the scan weighed it): N particles resolve the
  posterior no finer than that, so one scan that puts all weight on a few particles of a
  spread cloud does not read as certainty.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from lowerbase.world.localization.likelihood import LikelihoodField
from lowerbase.world.localization.params import AmclParams
from lowerbase.world.localization.poses import Pose2D, wrap

#: the cluster histogram is built over the occupied bins' bounding box; beyond this many
#: cells (a cloud spread over a huge map) the whole set is taken as one cluster
_MAX_CLUSTER_CELLS = 8_000_000
#: amcl's pf ``dist_threshold`` [m]: the set has converged when every particle is this close
#: to the mean in x and in y (beam skipping is done only then)
CONVERGED_DIST = 0.5


def systematic_indices(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Low-variance resampling: ``n`` indices drawn with one random offset."""
    if n <= 0:
        return np.zeros(0, dtype=np.int64)
    cdf = np.cumsum(weights)
    cdf[-1] = 1.0
    u = (rng.random() + np.arange(n)) / n
    return np.searchsorted(cdf, u, side="left")


def kld_limit(k: np.ndarray, params: AmclParams) -> np.ndarray:
    """amcl's ``pf_resample_limit``: particles needed for ``k`` occupied bins."""
    k = np.asarray(k, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    b = 2.0 / (9.0 * km1)
    x = 1.0 - b + np.sqrt(b) * params.kld_z
    n = np.ceil(km1 / (2.0 * params.kld_err) * x ** 3)
    n = np.where(k <= 1, params.max_particles, n)
    return np.clip(n, params.min_particles, params.max_particles).astype(np.int64)


def bin_keys(poses: np.ndarray, params: AmclParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ix = np.floor(poses[:, 0] / params.kld_bin_xy).astype(np.int64)
    iy = np.floor(poses[:, 1] / params.kld_bin_xy).astype(np.int64)
    na = math.ceil(2 * math.pi / params.kld_bin_yaw)
    ia = np.floor((poses[:, 2] + math.pi) / params.kld_bin_yaw).astype(np.int64) % na
    return ix, iy, ia


def kld_count(poses: np.ndarray, params: AmclParams, order: np.ndarray | None = None) -> int:
    """How many of ``poses`` (in the order given; ``order``: in the order ``poses[order]``)
    KLD-sampling keeps. The count is taken by a compiled scan that stops where it stops
    (:mod:`pf_kernel`); :func:`kld_count_numpy` is the numpy count it replaced."""
    from lowerbase.world.localization.pf_kernel import kld_count_poses

    n = poses.shape[0]
    if n == 0:
        return 0
    if order is None:
        order = np.arange(n)
    return int(kld_count_poses(
        np.ascontiguousarray(poses[:, 0]), np.ascontiguousarray(poses[:, 1]),
        np.ascontiguousarray(poses[:, 2]), np.asarray(order, dtype=np.int64),
        float(params.kld_bin_xy), float(params.kld_bin_yaw),
        math.ceil(2 * math.pi / params.kld_bin_yaw), math.pi, _limit_table(params, n),
        int(params.min_particles)))


_LIMITS: dict[tuple[float, float, int, int, int], np.ndarray] = {}


def _limit_table(params: AmclParams, n: int) -> np.ndarray:
    """``kld_limit(k)`` for k = 0 .. n (elementwise numpy: the same floats as computed for
    any other array of k)."""
    key = (params.kld_err, params.kld_z, params.min_particles, params.max_particles, n)
    table = _LIMITS.get(key)
    if table is None:
        if len(_LIMITS) > 16:
            _LIMITS.clear()
        table = _LIMITS[key] = kld_limit(np.arange(n + 1), params)
    return table


def _bin_index(poses: np.ndarray, params: AmclParams) -> np.ndarray:
    """One integer per histogram bin of ``poses`` (x, y, heading)."""
    ix, iy, ia = bin_keys(poses, params)
    ix, iy = ix - ix.min(), iy - iy.min()
    return (ix * (int(iy.max()) + 1) + iy) * 64 + ia


def kld_count_numpy(poses: np.ndarray, params: AmclParams) -> int:
    """:func:`kld_count` in numpy (the reference the compiled count is tested against)."""
    key = _bin_index(poses, params)
    _, first = np.unique(key, return_index=True)
    new_bin = np.zeros(key.size, dtype=bool)
    new_bin[first] = True
    k = np.cumsum(new_bin)
    n = np.arange(1, key.size + 1)
    done = np.flatnonzero((n > kld_limit(k, params)) & (n >= params.min_particles))
    return int(done[0] + 1) if done.size else int(key.size)


def cluster_labels(poses: np.ndarray, params: AmclParams) -> np.ndarray:
    """Cluster id per particle: connected occupied histogram bins, heading wrapping round
    (compiled, :func:`pf_kernel.cluster_ids`: the partition of :func:`cluster_labels_ndimage`,
    its ids in the same order, numbered from 0)."""
    from lowerbase.world.localization.pf_kernel import cluster_ids

    ix, iy, ia = bin_keys(poses, params)
    ix, iy = ix - ix.min(), iy - iy.min()
    na = math.ceil(2 * math.pi / params.kld_bin_yaw)
    ny = int(iy.max()) + 1
    if (int(ix.max()) + 1) * ny * (na + 1) > _MAX_CLUSTER_CELLS:
        return np.zeros(poses.shape[0], dtype=np.int64)
    return np.asarray(cluster_ids(ix, iy, ia, ny, na))


def cluster_labels_ndimage(poses: np.ndarray, params: AmclParams) -> np.ndarray:
    """:func:`cluster_labels` by scipy's ``ndimage.label`` and a union of the wrapped heading
    bins (the reference)."""
    ix, iy, ia = bin_keys(poses, params)
    ix, iy = ix - ix.min(), iy - iy.min()
    na = math.ceil(2 * math.pi / params.kld_bin_yaw)
    shape = (int(ix.max()) + 1, int(iy.max()) + 1, na + 1)
    if shape[0] * shape[1] * shape[2] > _MAX_CLUSTER_CELLS:
        return np.zeros(poses.shape[0], dtype=np.int64)
    occ = np.zeros(shape, dtype=bool)
    occ[ix, iy, ia] = True
    occ[:, :, na] = occ[:, :, 0]  # heading bin 0 again, after the last one
    labels, count = ndimage.label(occ, structure=np.ones((3, 3, 3), dtype=bool))
    root = np.arange(count + 1)

    def find(a: int) -> int:
        while root[a] != a:
            root[a] = root[root[a]]
            a = int(root[a])
        return a

    wrapped = occ[:, :, 0]
    pairs = np.unique(np.column_stack((labels[:, :, 0][wrapped], labels[:, :, na][wrapped])),
                      axis=0)
    for a, b in pairs:
        ra, rb = find(int(a)), find(int(b))
        if ra != rb:
            root[max(ra, rb)] = min(ra, rb)
    roots = np.array([find(i) for i in range(count + 1)])
    return roots[labels[ix, iy, ia]]


class ParticleSet:
    """Poses (N x 3) and normalised weights, with augmented MCL's averages."""

    def __init__(self, params: AmclParams, rng: np.random.Generator) -> None:
        self.params = params
        self.rng = rng
        self.poses = np.zeros((params.max_particles, 3))
        self.weights = np.full(params.max_particles, 1.0 / params.max_particles)
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.last_fit = 0.0
        self.prior_cov = np.zeros((3, 3))

    @property
    def count(self) -> int:
        return int(self.poses.shape[0])

    def _reset(self, poses: np.ndarray) -> None:
        self.poses = poses
        self.weights = np.full(poses.shape[0], 1.0 / poses.shape[0])
        self.w_slow = self.w_fast = 0.0

    def init_gaussian(self, mean: Pose2D, cov3: np.ndarray) -> None:
        """max_particles drawn from N(mean, cov3) (amcl's pf_init; heading wrapped)."""
        poses = self.rng.multivariate_normal(np.asarray(mean), cov3, self.params.max_particles,
                                             method="eigh")
        poses[:, 2] = wrap(poses[:, 2])
        self._reset(poses)

    def init_uniform(self, field: LikelihoodField) -> None:
        """max_particles uniform over the free space (amcl's global localization)."""
        self._reset(field.uniform_poses(self.params.max_particles, self.rng))

    def correct(self, log_p: np.ndarray, cube_model: bool, beams: int) -> None:
        """Weigh by the laser model's ``log p`` and update w_slow / w_fast."""
        if beams == 0:
            return
        self.prior_cov = weighted_cov(self.poses, self.weights, None)
        lw = np.log(np.maximum(self.weights, 1e-300)) + log_p
        lw -= lw.max()
        w = np.exp(lw)
        self.weights = w / w.sum()
        raw = log_p / self.params.laser_likelihood_exponent
        per_beam = np.expm1(raw) / beams if cube_model else np.exp(raw / beams)
        fit = float(np.dot(self.weights, per_beam))
        self.last_fit = fit
        if self.w_slow == 0.0:
            self.w_slow = self.w_fast = fit
        else:
            self.w_slow += self.params.recovery_alpha_slow * (fit - self.w_slow)
            self.w_fast += self.params.recovery_alpha_fast * (fit - self.w_fast)

    def converged(self) -> bool:
        """amcl's ``pf_update_converged``: every particle within ``CONVERGED_DIST`` of the
        particles' mean in x and in y."""
        xy = self.poses[:, :2]
        return bool(np.all(np.abs(xy - xy.mean(axis=0)) <= CONVERGED_DIST))

    @property
    def n_eff(self) -> float:
        return float(1.0 / np.sum(self.weights ** 2))

    @property
    def w_diff(self) -> float:
        """The fraction of random particles the next resampling injects (0 when off)."""
        p = self.params
        if self.w_slow <= 0.0 or p.recovery_alpha_fast == 0.0 or p.recovery_alpha_slow == 0.0:
            return 0.0
        d = max(0.0, 1.0 - self.w_fast / self.w_slow)
        return d if d > p.recovery_min_w_diff else 0.0

    def resample_due(self) -> bool:
        return self.n_eff < self.params.resample_ess * self.count or self.w_diff > 0.0

    def resample(self, field: LikelihoodField) -> int:
        """Low-variance resampling with recovery particles and KLD count; returns injected."""
        p = self.params
        m = p.max_particles
        w_diff = self.w_diff
        n_rand = int(self.rng.binomial(m, w_diff)) if w_diff > 0 else 0
        kept = self.poses[systematic_indices(self.weights, m - n_rand, self.rng)]
        new = np.concatenate((kept, field.uniform_poses(n_rand, self.rng))) if n_rand else kept
        if p.kld_sampling:  # new[perm][:count], only the rows kept gathered
            perm = self.rng.permutation(m)
            new = new[perm[:kld_count(new, p, perm)]]
        n_rand_kept = round(n_rand * new.shape[0] / m)
        self.poses = np.ascontiguousarray(new)
        self.weights = np.full(new.shape[0], 1.0 / new.shape[0])
        return n_rand_kept

    def estimate(self) -> tuple[Pose2D, np.ndarray, float]:
        """(mean of the heaviest cluster, 3x3 covariance about it, that cluster's weight)."""
        labels = cluster_labels(self.poses, self.params)
        mass = np.bincount(labels, weights=self.weights)
        best = int(np.argmax(mass))
        sel = labels == best
        w = self.weights[sel] / mass[best]
        mean = weighted_mean(self.poses[sel], w)
        h2 = ((4.0 / 5.0) ** (1.0 / 7.0) * self.count ** (-1.0 / 7.0)) ** 2
        cov = weighted_cov(self.poses, self.weights, mean) + h2 * self.prior_cov
        return mean, cov, float(mass[best])


def weighted_mean(poses: np.ndarray, w: np.ndarray) -> Pose2D:
    """Weighted mean (``w`` sums to 1), circular for the heading."""
    return (float(w @ poses[:, 0]), float(w @ poses[:, 1]),
            math.atan2(float(w @ np.sin(poses[:, 2])), float(w @ np.cos(poses[:, 2]))))


def weighted_cov(poses: np.ndarray, w: np.ndarray, about: Pose2D | None) -> np.ndarray:
    """``sum w (p - about)(p - about)^T`` (heading wrapped); about the weighted mean if None."""
    mx, my, myaw = weighted_mean(poses, w) if about is None else about
    d = np.column_stack((poses[:, 0] - mx, poses[:, 1] - my, wrap(poses[:, 2] - myaw)))
    cov = (d * w[:, None]).T @ d
    return 0.5 * (cov + cov.T)
