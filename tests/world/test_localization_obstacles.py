"""amcl near an obstacle the map does not know: the trace diagram's crate in the warehouse.

The route of tests/trace (y = 1.2 m along the warehouse's long bottom corridor) with the 0.4 m
crate on it at x = 13: the robot drives up to it, turns and goes round it (0.8 m off the line)
and back. The scans (the profile's two lidars, merged) see the crate, the map does not. amcl's
recovery (w_slow / w_fast) read the crate's beams as a kidnap and scattered particles over the
repetitive warehouse until a look-alike aisle won. Checked against the truth the drive is made of.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.clock import SimClock
from lowerbase.world.lidar import Lidar, LidarConfig, LidarRig
from lowerbase.world.localization import AmclParams, Localizer
from lowerbase.world.localization.likelihood import LikelihoodField
from lowerbase.world.localization.poses import Pose2D
from lowerbase.world.maps import load_map
from lowerbase.world.obstacles import obstacles_from_dicts
from lowerbase.world.raycast import Scene, Solid
from lowerbase.world.sensors import sensors_from_profile_file
from tests.world.localization_sim import drifting_odometry, feature_room, path_poses, pose_error

Y = 1.2
CRATE = {"kind": "box", "name": "crate", "center": [13.0, Y], "size": [0.4, 0.4]}
#: up to the crate, round it 0.8 m off the line, back onto the line and on
DETOUR: list[Pose2D] = [(6.0, Y, 0.0), (11.8, Y, 0.0), (12.4, 2.0, 0.0), (13.6, 2.0, 0.0),
                        (14.2, Y, 0.0), (21.0, Y, 0.0)]


def crate_drive(seed: int, params: AmclParams | None = None
                ) -> tuple[Localizer, list[tuple[float, float, bool]]]:
    """The detour at 0.5 m/s, a scan every 0.2 s; (error [m], |yaw error| [rad], lost) of
    every filter update."""
    grid = load_map("warehouse")
    crate = obstacles_from_dicts([CRATE])
    scene = Scene(grid).with_solids(Solid(p.height, p.polygon, p.circle, p.name)
                                    for p in crate.prisms_at(0.0))
    rig = LidarRig(sensors_from_profile_file().lidars, sensors_from_profile_file().scan)
    truth = path_poses(DETOUR)
    odom = drifting_odometry(truth, scale=1.01, yaw_rate_bias=0.0005)
    clock = SimClock()
    tight = np.diag([0.05 ** 2, 0.05 ** 2, math.radians(3) ** 2])
    loc = Localizer(grid, params, clock=clock, seed=seed, initial_pose=truth[0], initial_cov=tight)
    out = []
    for i, (tp, op) in enumerate(zip(truth, odom, strict=True)):
        clock.advance(0.1)
        if i % 2:
            continue
        est = loc.update(op, rig.scan(scene, tp, clock.now()))  # type: ignore[arg-type]
        if est is not None:
            pos, yaw = pose_error(est.pose, tp)
            out.append((pos, yaw, est.lost))
    return loc, out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_estimate_stays_on_the_robot_round_an_unmapped_crate(seed: int) -> None:
    loc, results = crate_drive(seed)
    assert len(results) > 50
    assert loc.stats.injected == 0  # nothing was kidnapped: recovery had no cause to fire
    pos = np.array([r[0] for r in results])
    yaw = np.array([r[1] for r in results])
    assert pos.max() < 0.15 and math.degrees(float(yaw.max())) < 3.0
    assert np.percentile(pos, 95) < 0.08
    assert not any(r[2] for r in results[3:])


def test_without_beam_skipping_the_crate_reads_as_a_kidnap() -> None:
    """amcl's default (no beam skipping) with augmented MCL on (amcl's suggested values): the
    crate's beams alone set recovery off."""
    loc, results = crate_drive(0, AmclParams(do_beamskip=False, recovery_alpha_slow=0.001,
                                             recovery_alpha_fast=0.1))
    assert loc.stats.injected > 0
    assert max(r[0] for r in results) > 1.0


def test_beam_skipping_leaves_out_the_beams_on_an_unmapped_box() -> None:
    grid = feature_room()
    pose = (6.5, 3.5, 0.0)
    box = Solid(1.0, np.array([[7.5, 3.2], [7.9, 3.2], [7.9, 3.8], [7.5, 3.8]]))
    lidar = Lidar(LidarConfig(fov=2 * math.pi, angular_step=math.radians(1.0), range_max=10.0,
                              range_sigma=0.0))
    scan = lidar.scan(Scene(grid).with_solids([box]), pose, 0.0)
    field = LikelihoodField(grid, AmclParams(laser_max_beams=360))
    beams = field.beams(scan)  # type: ignore[arg-type]
    rng = np.random.default_rng(4)
    cloud = np.column_stack((rng.normal(pose[0], 0.03, 500), rng.normal(pose[1], 0.03, 500),
                             rng.normal(0.0, 0.01, 500)))
    on_box = np.flatnonzero((np.abs(beams.end_xy[:, 0] - 1.0) < 0.05)
                            & (np.abs(beams.end_xy[:, 1]) <= 0.3))
    assert on_box.size > 10
    near = field.distances(np.asarray(pose), beams) < 0.5
    log_all, _, n_all = field.score(cloud, beams)
    log_skip, _, n_skip = field.score(cloud, beams, skip=True)
    assert n_all == beams.end_xy.shape[0]
    assert n_skip == int(near.sum()) and n_all - n_skip >= on_box.size
    assert np.all(log_skip > log_all)  # the box's beams no longer weigh the true pose down
    # a cloud where no beam agrees (off the map): all are used (amcl's error case)
    far = cloud + np.array([100.0, 0.0, 0.0])
    assert field.score(far, beams, skip=True)[2] == n_all
