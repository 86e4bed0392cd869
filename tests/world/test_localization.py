"""The particle filter localizer: models against closed forms, drives on simulated time, controls.

Drives: truth poses step along a path (0.1 s steps, 0.5 m/s); odometry is the truth's
increments with a known drift (2 % scale, a heading bias); scans are ray-cast from the truth
by lowerbase.world.lidar with 1 cm noise (tests/world/localization_sim.py). Every random
source is seeded.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from lowerbase.clock import SimClock
from lowerbase.errors import ConfigError, WorldError
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.localization import AmclParams, Localizer, PoseEstimate
from lowerbase.world.localization.likelihood import LikelihoodField
from lowerbase.world.localization.motion import odom_delta, sample_diff
from lowerbase.world.localization.particles import (
    cluster_labels,
    cluster_labels_ndimage,
    kld_count,
    kld_count_numpy,
    kld_limit,
    systematic_indices,
)
from lowerbase.world.localization.poses import Pose2D, compose, inverse
from tests.world.localization_sim import (
    cast,
    corridor,
    drifting_odometry,
    feature_room,
    in_free_space,
    path_poses,
    pose_error,
)

LOOP = [(1.5, 0.7, 0.0), (10.0, 0.7, 0.0), (10.0, 3.5, 0.0), (10.2, 6.2, 0.0), (4.5, 6.2, 0.0),
        (1.5, 2.5, 0.0), (7.0, 3.5, 0.0)]
TIGHT = np.diag([0.05 ** 2, 0.05 ** 2, math.radians(3) ** 2])


def drive(loc: Localizer, grid: OccupancyGrid, truth: list[Pose2D], odom: list[Pose2D],
          clock: SimClock, every: int = 2, seed: int = 1
          ) -> list[tuple[int, PoseEstimate, Pose2D]]:
    """Feed the localizer a scan every ``every`` steps; the (step, estimate, truth) it answered."""
    rng = np.random.default_rng(seed)
    out = []
    for i, (tp, op) in enumerate(zip(truth, odom, strict=True)):
        clock.advance(0.1)
        if i % every:
            continue
        est = loc.update(op, cast(grid, tp, rng=rng))
        if est is not None:
            out.append((i, est, tp))
    return out


# -- models against closed forms ----------------------------------------------------------------
def test_motion_model_without_noise_moves_each_particle_by_the_odometry_step() -> None:
    old, new = (1.0, 2.0, 0.3), (1.8, 2.5, 1.1)
    particles = np.array([[0.0, 0.0, 0.0], [5.0, -1.0, 2.0]])
    sample_diff(particles, old, new, (0.0, 0.0, 0.0, 0.0), np.random.default_rng(0))
    step = compose(inverse(old), new)
    for got, start in zip(particles, [(0.0, 0.0, 0.0), (5.0, -1.0, 2.0)], strict=True):
        assert got == pytest.approx(compose(start, step), abs=1e-12)


def test_motion_model_noise_has_amcls_standard_deviations() -> None:
    # a pure 1 m translation: trans sigma = sqrt(a3) * 1, rotations sigma = sqrt(a2) * 1
    a = (0.0, 0.01, 0.04, 0.0)
    particles = np.zeros((200_000, 3))
    sample_diff(particles, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), a, np.random.default_rng(1))
    rot1, trans, rot2 = odom_delta((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    assert (rot1, trans, rot2) == (0.0, 1.0, 0.0)
    dist = np.hypot(particles[:, 0], particles[:, 1])
    assert np.std(dist) == pytest.approx(0.2, rel=0.02)          # sqrt(0.04 * 1^2)
    assert np.std(particles[:, 2]) == pytest.approx(math.sqrt(2 * 0.01), rel=0.02)  # rot1 + rot2
    assert np.mean(dist) == pytest.approx(1.0, abs=0.002)


def test_likelihood_field_is_the_distance_to_the_nearest_obstacle() -> None:
    grid = feature_room()
    field = LikelihoodField(grid, AmclParams(laser_likelihood_max_dist=5.0))
    occ = np.argwhere(grid.data >= 50)
    ox, oy = grid.cell_to_world(occ[:, 1], occ[:, 0])
    rng = np.random.default_rng(2)
    cells = zip(rng.integers(0, grid.width, 40), rng.integers(0, grid.height, 40), strict=True)
    for col, row in cells:
        cx, cy = grid.cell_to_world(col, row)
        brute = float(np.min(np.hypot(ox - cx, oy - cy)))
        assert field.dist[row * grid.width + col] == pytest.approx(min(brute, 5.0), abs=1e-5)


def test_kld_limit_is_amcls_formula_and_kld_count_adapts_to_the_spread() -> None:
    p = AmclParams(min_particles=10, max_particles=5000)
    b = 2 / 81
    expected = math.ceil(9 / 0.02 * (1 - b + math.sqrt(b) * 0.99) ** 3)
    assert kld_limit(np.array([10]), p)[0] == expected
    assert kld_limit(np.array([1]), p)[0] == 5000          # one bin: max_particles (as amcl)
    rng = np.random.default_rng(3)
    # about a corner of the 0.5 m x 0.5 m x 10 deg bins: 2 x 2 x 2 of them, amcl's limit 525
    tight = np.column_stack((rng.normal(2, 0.05, 5000), rng.normal(2, 0.05, 5000),
                             rng.normal(0, 0.02, 5000)))
    wide = np.column_stack((rng.uniform(0, 20, 5000), rng.uniform(0, 20, 5000),
                            rng.uniform(-3, 3, 5000)))
    assert kld_count(tight, p) == kld_limit(np.array([8]), p)[0] + 1 == 526
    assert kld_count(wide, p) == 5000


def test_kld_count_is_the_numpy_count() -> None:
    """The compiled count (pf_kernel) against the numpy count it replaced, in the given order
    and in a permuted order (resample's ``poses[perm]``), spreads from one bin to thousands."""
    rng = np.random.default_rng(9)
    for params in (AmclParams(), AmclParams(min_particles=10, max_particles=3000),
                   AmclParams(min_particles=500, kld_err=0.05)):
        for spread in (0.0, 0.02, 0.1, 0.4, 3.0):
            n = params.max_particles
            poses = np.column_stack((rng.normal(4.0, spread + 1e-9, n),
                                     rng.normal(-2.0, spread + 1e-9, n),
                                     rng.normal(0.5, 0.3 * spread + 1e-9, n)))
            perm = rng.permutation(n)
            assert kld_count(poses, params) == kld_count_numpy(poses, params)
            assert kld_count(poses, params, perm) == kld_count_numpy(poses[perm], params)


def test_cluster_labels_are_the_ndimage_clusters_in_the_same_order() -> None:
    """The compiled clusters (pf_kernel.cluster_ids) against ndimage.label's with the heading
    wrapped: the same partition, and the ids in the same order (the heaviest cluster's ties go
    the same way): one cloud, two and three modes, clouds across the +-pi heading seam and
    along a bin edge, a single particle."""
    rng = np.random.default_rng(12)
    params = AmclParams()
    clouds = []
    for _ in range(30):
        modes = int(rng.integers(1, 4))
        parts = []
        for _ in range(modes):
            m = int(rng.integers(1, 400))
            centre = rng.uniform(-5.0, 5.0, 3)
            spread = rng.uniform(0.01, 1.0)
            parts.append(np.column_stack((rng.normal(centre[0], spread, m),
                                          rng.normal(centre[1], spread, m),
                                          rng.normal(centre[2], 3.0 * spread, m))))
        poses = np.concatenate(parts)
        poses[:, 2] = np.mod(poses[:, 2] + math.pi, 2 * math.pi) - math.pi
        clouds.append(poses)
    seam = np.column_stack((rng.normal(1.0, 0.2, 300), rng.normal(1.0, 0.2, 300),
                            rng.choice([-1.0, 1.0], 300) * rng.uniform(3.05, math.pi, 300)))
    clouds += [seam, np.array([[0.3, -0.2, 0.1]])]
    for poses in clouds:
        got = cluster_labels(poses, params)
        want = cluster_labels_ndimage(poses, params)
        assert np.array_equal(np.sign(got[:, None] - got[None, :]),
                              np.sign(want[:, None] - want[None, :]))
    assert len(set(cluster_labels(seam, params))) == 1  # one cloud across the seam


def test_systematic_resampling_keeps_each_particle_in_proportion() -> None:
    w = np.array([0.5, 0.25, 0.125, 0.125])
    idx = systematic_indices(w, 8000, np.random.default_rng(4))
    assert np.bincount(idx, minlength=4).tolist() == [4000, 2000, 1000, 1000]


# -- drives ---------------------------------------------------------------------------------------
def test_tracking_from_a_good_initial_pose_keeps_the_error_small() -> None:
    grid = feature_room()
    truth = path_poses(LOOP)
    assert in_free_space(grid, truth)
    odom = drifting_odometry(truth)
    clock = SimClock()
    loc = Localizer(grid, clock=clock, seed=3, initial_pose=truth[0], initial_cov=TIGHT)
    results = drive(loc, grid, truth, odom, clock)
    assert len(results) > 100
    pos = np.array([pose_error(e.pose, t)[0] for _, e, t in results])
    yaw = np.array([pose_error(e.pose, t)[1] for _, e, t in results])
    assert np.percentile(pos, 95) < 0.08 and pos.max() < 0.2
    assert math.degrees(float(np.percentile(yaw, 95))) < 2.0
    assert sum(e.lost for _, e, _ in results[3:]) <= 0.02 * len(results)
    # odometry alone drifts far more: the filter is doing the work
    odom_err = pose_error(compose(compose(truth[0], inverse(odom[0])), odom[-1]), truth[-1])[0]
    assert odom_err > 5 * pos[-10:].max()
    # between updates, movebase_pose2d is map->odom composed with the current odom pose
    i, est, _ = results[-1]
    assert loc.pose_from_odom(odom[i]) == pytest.approx(est.pose, abs=1e-9)


def test_covariance_is_consistent_with_the_true_error() -> None:
    grid = feature_room()
    truth = path_poses(LOOP)
    odom = drifting_odometry(truth)
    clock = SimClock()
    loc = Localizer(grid, clock=clock, seed=5, initial_pose=truth[0], initial_cov=TIGHT)
    results = drive(loc, grid, truth, odom, clock, seed=6)[3:]
    within = []
    for _, est, t in results:
        d = np.array([est.pose[0] - t[0], est.pose[1] - t[1]])
        cov = np.array(est.cov)[:2, :2]
        within.append(float(d @ np.linalg.solve(cov, d)) <= 3.0 ** 2)
    assert np.mean(within) >= 0.9                    # within 3 sigma (2D) most of the time
    sigmas = np.array([e.sigma_xy for _, e, _ in results])
    assert np.median(sigmas) < 0.15                  # and not honest by being uselessly wide


def test_global_initialisation_converges_in_a_feature_rich_room() -> None:
    grid = feature_room()
    truth = path_poses(LOOP)
    odom = drifting_odometry(truth)
    clock = SimClock()
    loc = Localizer(grid, clock=clock, seed=7, global_init=True)
    results = drive(loc, grid, truth, odom, clock)
    assert results[0][1].lost                        # one scan cannot place it honestly
    last = results[-20:]
    assert all(pose_error(e.pose, t)[0] < 0.15 and not e.lost for _, e, t in last)


def test_a_wrong_initial_pose_reads_lost_until_global_localization_recovers() -> None:
    grid = feature_room()
    truth = path_poses(LOOP)
    odom = drifting_odometry(truth)
    clock = SimClock()
    wrong = (8.0, 3.8, 2.0)
    loc = Localizer(grid, clock=clock, seed=8, initial_pose=wrong, initial_cov=TIGHT)
    half = len(truth) // 3
    first = drive(loc, grid, truth[:half], odom[:half], clock)
    # it never trusted a wrong pose: lost whenever it is more than 0.5 m off
    assert first and all(e.lost for _, e, t in first if pose_error(e.pose, t)[0] > 0.5)
    assert first[0][1].lost
    loc.global_localization()                        # amcl's /global_localization
    second = drive(loc, grid, truth[half:], odom[half:], clock)
    assert second[0][1].lost
    assert all(pose_error(e.pose, t)[0] < 0.15 and not e.lost for _, e, t in second[-20:])


def test_kidnapping_is_detected_and_recovered() -> None:
    grid = feature_room()
    leg_a = path_poses(LOOP[:4])
    leg_b = path_poses([(4.0, 4.0, 0.0), (4.5, 6.2, 0.0), (1.5, 2.5, 0.0), (7.0, 3.5, 0.0),
                        (10.0, 0.7, 0.0), (10.0, 3.5, 0.0)])
    truth = leg_a + leg_b
    assert in_free_space(grid, truth)
    odom = drifting_odometry(truth, teleports=(len(leg_a),))
    clock = SimClock()
    # augmented MCL on, with amcl's suggested values (amcl's and lowerbase's default: off)
    recovery = AmclParams(recovery_alpha_slow=0.001, recovery_alpha_fast=0.1)
    loc = Localizer(grid, recovery, clock=clock, seed=9, initial_pose=truth[0],
                    initial_cov=TIGHT)
    results = drive(loc, grid, truth, odom, clock)
    before = [r for r in results if r[0] < len(leg_a)]
    after = [r for r in results if r[0] >= len(leg_a)]
    assert all(not e.lost and pose_error(e.pose, t)[0] < 0.15 for _, e, t in before[3:])
    assert any(e.lost for _, e, _ in after[:5])      # the scan stops fitting at once
    recovered = [i for i, e, t in after if pose_error(e.pose, t)[0] < 0.15 and not e.lost]
    assert recovered
    tail = [r for r in after if r[0] >= recovered[0] + 50]
    assert tail and all(pose_error(e.pose, t)[0] < 0.2 and not e.lost for _, e, t in tail)


def test_a_featureless_corridor_loses_the_along_corridor_position() -> None:
    grid = corridor()
    truth = path_poses([(20.0, 1.0, 0.0), (40.0, 1.0, 0.0)])
    odom = drifting_odometry(truth, scale=1.0, yaw_rate_bias=0.0)
    clock = SimClock()
    params = AmclParams(odom_alpha3=0.05)
    loc = Localizer(grid, params, clock=clock, seed=10, initial_pose=truth[0], initial_cov=TIGHT)
    rng = np.random.default_rng(11)
    results = []
    for i, (tp, op) in enumerate(zip(truth, odom, strict=True)):
        clock.advance(0.1)
        est = loc.update(op, cast(grid, tp, range_max=8.0, rng=rng))
        if est is not None:
            results.append((i, est, tp))
    var_x = [e.cov[0][0] for _, e, _ in results]
    var_y = [e.cov[1][1] for _, e, _ in results]
    assert var_x[-1] > 10 * var_x[1] and var_x[-1] > 50 * var_y[-1]
    assert results[-1][1].lost and not results[1][1].lost
    assert all(abs(e.pose[1] - t[1]) < 0.05 for _, e, t in results)  # across: still known


# -- outputs --------------------------------------------------------------------------------------
def test_ros_covariance_layout_and_map_to_odom() -> None:
    cov = ((1.0, 2.0, 3.0), (2.0, 4.0, 5.0), (3.0, 5.0, 6.0))
    est = PoseEstimate(0.0, (1.0, 2.0, 0.5), cov, compose((1.0, 2.0, 0.5), inverse((3, 1, 0.2))),
                       "filter", 0.0, 0.0, 1.0, False, 100)
    c = est.covariance
    assert (c[0], c[1], c[5], c[7], c[11], c[35], c[30]) == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 3.0)
    assert sum(abs(v) for v in c) == pytest.approx(2 * (2 + 3 + 5) + 1 + 4 + 6)
    assert compose(est.map_to_odom, (3, 1, 0.2)) == pytest.approx((1.0, 2.0, 0.5))


def test_ground_truth_mode_publishes_the_truth() -> None:
    grid = feature_room()
    truth_now: list[Pose2D] = [(3.0, 3.0, 0.4)]
    clock = SimClock(5.0)
    loc = Localizer(grid, clock=clock, initial_pose=(3.0, 3.0, 0.0), truth=lambda: truth_now[0],
                    ground_truth=True)
    est = loc.update((0.1, 0.2, 0.3), cast(grid, truth_now[0]))
    assert est is not None and est.source == "truth"
    assert est.pose == pytest.approx(truth_now[0], abs=1e-12)
    assert est.stamp == 5.0 and not est.lost and est.fit > 0.9
    assert compose(est.map_to_odom, (0.1, 0.2, 0.3)) == pytest.approx(truth_now[0])
    loc.set_ground_truth(False)
    assert loc.update((0.1, 0.2, 0.3), cast(grid, truth_now[0])).source == "filter"  # type: ignore[union-attr]
    with pytest.raises(WorldError, match="truth source"):
        Localizer(grid, clock=clock, initial_pose=(3.0, 3.0, 0.0), ground_truth=True)


# -- controls and bad input -------------------------------------------------------------------
def _state(loc: Localizer) -> tuple[OccupancyGrid, np.ndarray, PoseEstimate | None]:
    return loc.grid, loc.particles.copy(), loc.last


def test_start_stop_has_setbool_semantics() -> None:
    grid = feature_room()
    clock = SimClock()
    loc = Localizer(grid, clock=clock, initial_pose=(3.0, 3.0, 0.0))
    scan = cast(grid, (3.0, 3.0, 0.0))
    assert loc.start(False) == (True, "localization stopped")
    assert loc.start(False) == (True, "localization already stopped")
    assert loc.update((0, 0, 0), scan) is None and loc.stats.dropped_stopped == 1
    assert loc.start(True) == (True, "localization started")
    assert loc.update((0, 0, 0), scan) is not None


@pytest.mark.parametrize("pose, message", [
    ((float("nan"), 1.0, 0.0), "three finite numbers"),
    ((1.0, 2.0), "three finite numbers"),
    ((30.0, 2.0, 0.0), "outside the map"),
    ((1e300, -1e300, 0.0), r"^initial pose \(1e\+300, -1e\+300\) is outside the map"),
    ((5.2, 1.5, 0.0), "not in free space"),   # inside the box (5.0..5.4, 1.0..2.6)
])
def test_bad_poses_are_refused_and_nothing_changes(pose: tuple, message: str) -> None:
    grid = feature_room()
    clock = SimClock()
    loc = Localizer(grid, clock=clock, initial_pose=(3.0, 3.0, 0.0))
    loc.update((0, 0, 0), cast(grid, (3.0, 3.0, 0.0)))
    before = _state(loc)
    other = corridor()
    for call in (lambda: loc.initial_pose(pose), lambda: loc.set_map(grid, pose)):
        with pytest.raises(WorldError, match=message):
            call()
        after = _state(loc)
        assert after[0] is before[0] and np.array_equal(after[1], before[1])
        assert after[2] is before[2]
    with pytest.raises(WorldError, match="outside the map"):
        loc.set_map(other, (30.0, 5.0, 0.0))       # valid on the old map, not on the new one
    assert loc.grid is grid
    with pytest.raises(WorldError):
        Localizer(grid, clock=clock, initial_pose=pose)  # type: ignore[arg-type]


def test_bad_covariances_and_maps_are_refused() -> None:
    grid = feature_room()
    clock = SimClock()
    loc = Localizer(grid, clock=clock, initial_pose=(3.0, 3.0, 0.0))
    before = loc.particles.copy()
    for cov, message in ((np.full(9, np.nan), "finite"), ([1.0, 2.0], "9 or 36"),
                         (np.diag([1.0, -1.0, 1.0]), "semi-definite"),
                         ([[1, 2, 0], [0, 1, 0], [0, 0, 1]], "symmetric")):
        with pytest.raises(WorldError, match=message):
            loc.initial_pose((3.0, 3.0, 0.0), cov)
    full = OccupancyGrid(np.full((10, 10), 100, dtype=np.int8), 0.05)
    with pytest.raises(WorldError, match="no free cells"):
        loc.set_map(full, (0.2, 0.2, 0.0))
    assert np.array_equal(loc.particles, before) and loc.grid is grid
    with pytest.raises(ConfigError, match="laser_sigma_hit"):
        AmclParams(laser_sigma_hit=0.0)


def test_bad_scans_and_odometry_are_counted_drops() -> None:
    grid = feature_room()
    clock = SimClock()
    loc = Localizer(grid, clock=clock, initial_pose=(3.0, 3.0, 0.0))
    good = cast(grid, (3.0, 3.0, 0.0))
    bad_scan = cast(grid, (3.0, 3.0, 0.0))
    bad_scan = dataclasses.replace(bad_scan, angle_increment=float("nan"))
    assert loc.update((float("inf"), 0, 0), good) is None
    assert loc.update((0, 0, 0), bad_scan) is None
    assert loc.update((0, 0, 0), object()) is None  # type: ignore[arg-type]
    assert loc.stats.dropped_bad_input == 3
    assert loc.update((0, 0, 0), good) is not None


def test_set_map_switches_maps_and_initial_pose_reinitialises() -> None:
    room, hall = feature_room(), corridor()
    clock = SimClock()
    loc = Localizer(room, clock=clock, seed=12, initial_pose=(3.0, 3.0, 0.0), initial_cov=TIGHT)
    loc.set_map(hall, (30.0, 1.0, 0.0), TIGHT)
    assert loc.grid is hall and loc.last is None
    est = loc.update((0, 0, 0), cast(hall, (30.0, 1.0, 0.0), range_max=8.0))
    assert est is not None and abs(est.pose[1] - 1.0) < 0.1
    ros_cov = np.zeros(36)
    ros_cov[[0, 7, 35]] = TIGHT[0, 0], TIGHT[1, 1], TIGHT[2, 2]
    loc.initial_pose((31.0, 0.8, 0.1), ros_cov)
    parts = loc.particles
    assert np.mean(parts[:, 0]) == pytest.approx(31.0, abs=0.01)
    assert np.std(parts[:, 1]) == pytest.approx(0.05, rel=0.1)
    assert np.std(parts[:, 2]) == pytest.approx(math.radians(3), rel=0.1)
