"""amcl's odometry motion model, "diff" (Probabilistic Robotics, table 5.6), on all particles.

The odometry step between two /odom poses is split into rotate (rot1), translate, rotate
(rot2); each is perturbed by zero-mean Gaussian noise whose standard deviation is
``sqrt(alpha1 rot^2 + alpha2 trans^2)`` (rotations) and
``sqrt(alpha3 trans^2 + alpha4 (rot1^2 + rot2^2))`` (translation), exactly as amcl's
``AMCLOdom::UpdateAction`` (ODOM_MODEL_DIFF) does, where a rotation's size is taken modulo a
half turn (driving backwards is a small rotation, not a half turn).
"""

from __future__ import annotations

import math

import numpy as np

from lowerbase.world.localization.poses import Pose2D, wrap, wrap_scalar


def _angle_diff(a: float, b: float) -> float:
    return wrap_scalar(a - b)


def odom_delta(old: Pose2D, new: Pose2D) -> tuple[float, float, float]:
    """(rot1, trans, rot2) of the step ``old -> new`` (amcl: 0 rot1 under 1 cm of travel)."""
    dx, dy = new[0] - old[0], new[1] - old[1]
    trans = math.hypot(dx, dy)
    rot1 = 0.0 if trans < 0.01 else _angle_diff(math.atan2(dy, dx), old[2])
    rot2 = _angle_diff(_angle_diff(new[2], old[2]), rot1)
    return rot1, trans, rot2


def sample_diff(particles: np.ndarray, old: Pose2D, new: Pose2D,
                alphas: tuple[float, float, float, float], rng: np.random.Generator,
                noise_of: Pose2D | None = None) -> None:
    """Move ``particles`` (N x 3, in place) by the odometry step ``old -> new`` with noise;
    ``noise_of``: the noise is that of the step ``old -> noise_of`` instead (the slip check
    cuts a step to what the base moved, the wheels' count stays as uncertain as it was)."""
    a1, a2, a3, a4 = alphas
    rot1, trans, rot2 = odom_delta(old, new)
    n_rot1, n_trans, n_rot2 = (rot1, trans, rot2) if noise_of is None \
        else odom_delta(old, noise_of)
    # the size of a rotation, ignoring its direction of travel (amcl's rot*_noise)
    r1n = min(abs(_angle_diff(n_rot1, 0.0)), abs(_angle_diff(n_rot1, math.pi)))
    r2n = min(abs(_angle_diff(n_rot2, 0.0)), abs(_angle_diff(n_rot2, math.pi)))
    n = particles.shape[0]
    noise = rng.standard_normal((3, n))
    rot1_hat = rot1 - noise[0] * math.sqrt(a1 * r1n * r1n + a2 * n_trans * n_trans)
    trans_hat = trans - noise[1] * math.sqrt(a3 * n_trans * n_trans
                                             + a4 * (r1n * r1n + r2n * r2n))
    rot2_hat = rot2 - noise[2] * math.sqrt(a1 * r2n * r2n + a2 * n_trans * n_trans)
    heading = particles[:, 2] + rot1_hat
    particles[:, 0] += trans_hat * np.cos(heading)
    particles[:, 1] += trans_hat * np.sin(heading)
    particles[:, 2] = wrap(heading + rot2_hat)
