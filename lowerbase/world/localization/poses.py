"""2D pose algebra (x [m], y [m], yaw [rad]), scalar and vectorised over particles.

``compose(a, b)`` is the pose b expressed in a's parent frame (a ⊕ b); ``inverse(a)`` is ⊖a.
"""

from __future__ import annotations

import math

import numpy as np

Pose2D = tuple[float, float, float]


def wrap(angle: np.ndarray | float) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def wrap_scalar(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def compose(a: Pose2D, b: Pose2D) -> Pose2D:
    ax, ay, ath = a
    c, s = math.cos(ath), math.sin(ath)
    return (ax + c * b[0] - s * b[1], ay + s * b[0] + c * b[1], wrap_scalar(ath + b[2]))


def inverse(a: Pose2D) -> Pose2D:
    ax, ay, ath = a
    c, s = math.cos(ath), math.sin(ath)
    return (-c * ax - s * ay, s * ax - c * ay, wrap_scalar(-ath))


def is_finite_pose(p: object) -> bool:
    """True for a sequence of three finite numbers."""
    try:
        values = [float(v) for v in p]  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        return False
    return len(values) == 3 and all(math.isfinite(v) for v in values)
