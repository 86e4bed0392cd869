"""The slip check: did the base move as far as /odom says? (lowerbase; amcl has none.)

Wheels that spin against a wall or a crate count distance the base never moved, and /odom
runs on with them. amcl's motion model takes that as motion: its noise
(``sqrt(alpha3 trans^2 + ...)``, 0.045 m per 0.2 m update at alpha3 0.05, 0.09 m at amcl's 0.2)
lets the scan hold the particles back only a few centimetres per update, so the estimate
follows /odom through the wall at the slip's speed, and once the particles are more than the
likelihood field's reach (``laser_sigma_hit``) off, the scan stops pulling at all.

Before each filter update the check scores the scan from the last estimate moved by a fraction
``s`` of the odometry step's translation (the rotations as /odom has them: the heading is the
gyro's and does not slip), ``s`` in ``0, 1/8, ..., 1``. When a fraction fits the map better
than the whole step by more than ``slip_min_log_ratio`` (the laser model's log-likelihood, as
the filter weighs it), the odometry step is cut to that fraction: the rest was wheel slip. It
is a one-dimensional correlative match against the map, on the beams the filter would use
(amcl's beam skipping among the candidates, so an unmapped crate's beams are left out).

A featureless stretch scores all fractions alike and keeps the whole step; an ordinary drive
fits best at ``s = 1`` and is left alone (tests/world/test_localization_slip.py).
"""

from __future__ import annotations

import math

import numpy as np

from lowerbase.world.localization.likelihood import Beams, LikelihoodField
from lowerbase.world.localization.motion import odom_delta
from lowerbase.world.localization.poses import Pose2D, wrap_scalar

#: the fractions of the odometry step's translation tried
FRACTIONS = np.linspace(0.0, 1.0, 9)


def step_poses(base: Pose2D, old: Pose2D, new: Pose2D, fractions: np.ndarray) -> np.ndarray:
    """``base`` moved by the odometry step ``old -> new`` with its translation scaled by each
    of ``fractions`` (rotate rot1, translate, rotate rot2, as the diff model splits it)."""
    rot1, trans, rot2 = odom_delta(old, new)
    heading = base[2] + rot1
    out = np.empty((fractions.size, 3))
    out[:, 0] = base[0] + fractions * trans * math.cos(heading)
    out[:, 1] = base[1] + fractions * trans * math.sin(heading)
    out[:, 2] = wrap_scalar(heading + rot2)
    return out


def scaled_odom(old: Pose2D, new: Pose2D, fraction: float) -> Pose2D:
    """The /odom pose after ``old`` had the step ``old -> new`` moved only ``fraction`` of its
    translation (its rotations whole)."""
    p = step_poses(old, old, new, np.array([fraction]))[0]
    return float(p[0]), float(p[1]), float(p[2])


def slip_fraction(field: LikelihoodField, beams: Beams, base: Pose2D, old: Pose2D,
                  new: Pose2D, min_log_ratio: float) -> float:
    """The fraction of the odometry step ``old -> new`` the scan says the base moved from
    ``base`` (its estimate at ``old``): 1.0 unless a smaller one fits the map better than the
    whole step by more than ``min_log_ratio``."""
    if beams.end_xy.shape[0] == 0:
        return 1.0
    poses = step_poses(base, old, new, FRACTIONS)
    log_p, _, _ = field.score(poses, beams, skip=True)
    best = int(np.argmax(log_p))
    if best == FRACTIONS.size - 1 or log_p[best] - log_p[-1] <= min_log_ratio:
        return 1.0
    return float(FRACTIONS[best])
