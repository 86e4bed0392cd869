"""amcl against a robot whose wheels slip (issue 22 item 24): the slip check.

A robot driven into a crate or a wall stops, its tyres slip and /odom runs on at the setpoint
(tests/world/test_blocked_traction.py). amcl's motion model takes that as motion, so the
estimate followed /odom through the crate (13 m after 27 s with augmented MCL off) or, with
augmented MCL on, scattered particles and jumped 21 m / 163 deg to a look-alike aisle. The slip
check (lowerbase/world/localization/slipcheck.py) cuts each odometry step to the fraction the
scan fits best.

The bounds: /amcl_pose (the filter's estimate at its update) within 0.1 m / 2 deg of the truth
once the robot pushes (the filter's ordinary error in this lane is a few cm); movebase_pose2d
(the last map -> odom on the current /odom) within ``update_min_d`` + 0.15 m, since /odom runs
on for ``update_min_d`` and up to a scan period more between two updates (as it would with ROS
amcl on a slipping robot: its map -> odom also changes only at updates), and it never jumps
further than that (the next update takes the slipped odometry back).
All on the simulated clock, seeded.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.clock import SimClock
from lowerbase.world.localization import AmclParams, Localizer
from lowerbase.world.localization.likelihood import LikelihoodField
from lowerbase.world.localization.poses import Pose2D, compose, wrap_scalar
from lowerbase.world.localization.slipcheck import scaled_odom, slip_fraction
from lowerbase.world.obstacles import Box, Obstacles
from lowerbase.world.sim import WorldConfig, WorldSim
from tests.world.localization_sim import (
    cast,
    corridor,
    drifting_odometry,
    feature_room,
    path_poses,
    pose_error,
)
from tests.world.test_localization import LOOP, TIGHT, drive
from tests.world.test_sim import started

CRATE = Box("crate", center=(6.0, 2.0), size=(0.8, 0.8), height=1.5)  # in the lane, tall
PUSH = 27.0  # [s] at 0.5 m/s: /odom runs about 11 m while the robot stands


class Push:
    """Drive at 0.5 m/s into what stops the robot; watch every period."""

    def __init__(self, start: Pose2D, obstacles: Obstacles, seed: int) -> None:
        self.w = started(WorldConfig(start=start, obstacles=obstacles, seed=seed))
        self.w.run(2.0)  # the EKF learns the gyro's bias standing
        self.odom0 = self.w.odom_pose()
        self.moves: list[float] = []      # [m] movebase_pose2d's move per period
        self.errors: list[tuple[float, float]] = []  # movebase_pose2d against the truth
        self.updates: list[tuple[float, float]] = []  # /amcl_pose against the truth, blocked
        self._last = self.w.amcl_pose()
        self._est = self.w.estimate
        self.w.drive(0.5, 0.0, PUSH, on_step=self._watch)

    def _watch(self, w: WorldSim) -> None:
        pose = w.amcl_pose()
        assert pose is not None and self._last is not None
        self.moves.append(math.hypot(pose[0] - self._last[0], pose[1] - self._last[1]))
        self._last = pose
        err = w.localization_error()
        assert err is not None
        self.errors.append(err)
        est = w.estimate
        if est is not None and est is not self._est:
            self._est = est
            if w.loop.mcu.truth.blocked:  # the scan's tick was this period or the last one
                t = w.true_pose()
                self.updates.append((math.hypot(est.pose[0] - t[0], est.pose[1] - t[1]),
                                     abs(wrap_scalar(est.pose[2] - t[2]))))


@pytest.mark.parametrize(("start", "obstacles"), [
    ((4.0, 2.0, 0.0), Obstacles([CRATE])),  # an unmapped crate: its beams are skipped
    ((26.0, 2.0, 0.0), Obstacles()),         # the warehouse's east wall, on the map
], ids=["crate", "wall"])
def test_a_robot_pushing_against_an_obstacle_stays_localized(start: Pose2D,
                                                             obstacles: Obstacles) -> None:
    run = Push(start, obstacles, seed=0)
    w = run.w
    odom, odom0 = w.odom_pose(), run.odom0
    assert odom is not None and odom0 is not None
    travelled = math.hypot(odom[0] - odom0[0], odom[1] - odom0[1])
    true_travel = math.hypot(w.true_pose()[0] - start[0], w.true_pose()[1] - start[1])
    assert travelled > true_travel + 9.0  # the wheels slipped: /odom ran on through it
    assert w.loop.mcu.truth.blocked and w.localizer.stats.slips > 20
    bound = w.localizer.params.update_min_d + 0.15
    assert len(run.updates) > 30
    assert max(p for p, _ in run.updates) < 0.1
    assert max(h for _, h in run.updates) < math.radians(2.0)
    assert max(p for p, _ in run.errors) < bound
    assert max(h for _, h in run.errors) < math.radians(5.0)
    assert max(run.moves) < bound  # no jump
    assert w.localizer.stats.injected == 0


def test_ordinary_drives_never_read_as_slip() -> None:
    """The feature room's loop with odometry 5 % long or 2 % short (and a heading bias):
    every step is taken whole; a lane drive in the warehouse too."""
    grid = feature_room()
    truth = path_poses(LOOP)
    for scale in (1.05, 0.98):
        clock = SimClock()
        loc = Localizer(grid, clock=clock, seed=1, initial_pose=truth[0], initial_cov=TIGHT)
        results = drive(loc, grid, truth, drifting_odometry(truth, scale=scale), clock)
        assert len(results) > 100 and loc.stats.slips == 0
    w = started(WorldConfig(start=(4.0, 2.0, 0.0), seed=4))
    w.drive(0.5, 0.3, 6.0)
    w.drive(0.5, 0.0, 10.0)
    assert w.localizer.stats.filter_updates > 20 and w.localizer.stats.slips == 0


@pytest.mark.parametrize("scale", [1.5, 2.0])
def test_odometry_that_overcounts_half_or_double_is_cut_to_the_scan(scale: float) -> None:
    """A partial slip: /odom counts 1.5x or 2x the truth's travel. The check cuts the steps
    and the estimate stays within 0.2 m (without it: 0.2-0.3 m and a scattered cloud)."""
    grid = feature_room()
    truth = path_poses(LOOP)
    results = {}
    for on in (True, False):
        clock = SimClock()
        loc = Localizer(grid, AmclParams(slip_check=on), clock=clock, seed=1,
                        initial_pose=truth[0], initial_cov=TIGHT)
        res = drive(loc, grid, truth, drifting_odometry(truth, scale=scale), clock)
        results[on] = (loc, max(pose_error(e.pose, t)[0] for _, e, t in res[3:]))
    loc, worst = results[True]
    assert loc.stats.slips > 100 and worst < 0.2
    assert results[False][1] > worst


def test_the_slip_fraction_is_what_the_scan_shows() -> None:
    """Closed cases: the scan from where the base stood (none of the step), from where the
    step ends (all of it), from half way, each within one of the tried fractions (the field
    is the map's 5 cm cells); a featureless corridor cannot tell: all of it."""
    grid = feature_room()
    field = LikelihoodField(grid, AmclParams())
    base: Pose2D = (4.0, 3.0, 0.3)
    old: Pose2D = (1.0, 1.0, 0.0)  # /odom: the same 0.3 m step, in another frame
    new = compose(old, (0.3, 0.0, 0.0))
    for moved in (0.0, 0.5, 1.0):
        scan = cast(grid, compose(base, (0.3 * moved, 0.0, 0.0)))
        frac = slip_fraction(field, field.beams(scan), base, old, new, 1.0)
        assert frac == pytest.approx(moved, abs=0.125)  # one of the 1/8 steps: 4 cm, < a cell
    long = corridor()
    lf = LikelihoodField(long, AmclParams())
    cbase: Pose2D = (30.0, 1.0, 0.0)
    scan = cast(long, cbase, range_max=8.0)  # the corridor's ends out of range
    assert slip_fraction(lf, lf.beams(scan), cbase, old, new, 1.0) == 1.0
    assert scaled_odom(old, new, 0.5) == pytest.approx(compose(old, (0.15, 0.0, 0.0)))
    turn = compose(old, (0.2, 0.0, 0.4))  # rotations are kept whole
    assert scaled_odom(old, turn, 0.0)[2] == pytest.approx(0.4)
    assert np.isfinite(scaled_odom(old, turn, 0.0)).all()
