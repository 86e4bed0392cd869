"""Leg kinematics (mini-cheetah leg: ab/ad, hip, knee) and the foot trajectories of standing
up, sitting down and a trot.

Leg frame: origin on the ab/ad axis, x forward, y left, z up. The ab/ad joint turns about x;
the thigh and the calf joints about y (positive knee folds the leg). ``side`` is -1 for a right
leg, +1 for a left one; with every joint at zero the leg hangs straight down below the hip,
offset by ``side * abad_link`` sideways.

The body controller's period runs this arithmetic compiled (:mod:`lowerbase.legged.kernels`);
these functions are its reference, and tests hold the kernel to them bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from lowerbase.errors import LowerbaseError

#: where each leg's hip is on the body, legs in the order FR, FL, RR, RL: ``SIDES`` is the
#: leg's ``side`` (-1 right, +1 left; times ``hip_y``), ``FRONT`` +1 ahead of the centre, -1
#: behind it (times ``hip_x``)
SIDES = (-1, 1, -1, 1)
FRONT = (1, 1, -1, -1)


class KinematicsError(LowerbaseError):
    """A foot position the leg cannot reach."""


@dataclass(frozen=True)
class LegGeometry:
    abad_link: float  #: ab/ad axis to the thigh plane [m]
    thigh: float  #: hip to knee [m]
    calf: float  #: knee to foot [m]
    hip_x: float  #: ab/ad axis ahead of the body centre [m]
    hip_y: float  #: ab/ad axis beside the body centre [m]


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def leg_fk(q: tuple[float, float, float], side: int, g: LegGeometry) -> tuple[float, ...]:
    """Foot position in the leg frame for joint angles q = (abad, hip, knee)."""
    q0, q1, q2 = q
    x = -g.thigh * math.sin(q1) - g.calf * math.sin(q1 + q2)
    zs = -g.thigh * math.cos(q1) - g.calf * math.cos(q1 + q2)
    ys = side * g.abad_link
    c, s = math.cos(q0), math.sin(q0)
    return (x, ys * c - zs * s, ys * s + zs * c)


def leg_ik(x: float, y: float, z: float, side: int, g: LegGeometry) -> tuple[float, float, float]:
    """Joint angles (abad, hip, knee >= 0) that put the foot at (x, y, z) in the leg frame."""
    r2 = y * y + z * z - g.abad_link ** 2
    if r2 <= 0.0:
        raise KinematicsError(f"foot ({x:.3f}, {y:.3f}, {z:.3f}) is inside the ab/ad offset")
    d = math.sqrt(r2)
    q0 = _wrap(math.atan2(z, y) - math.atan2(-d, side * g.abad_link))
    c2 = (x * x + r2 - g.thigh ** 2 - g.calf ** 2) / (2 * g.thigh * g.calf)
    if not -1.0 <= c2 <= 1.0:
        raise KinematicsError(f"foot ({x:.3f}, {y:.3f}, {z:.3f}) is out of the leg's reach")
    q2 = math.acos(c2)
    q1 = _wrap(math.atan2(x, -d)
               - math.atan2(-g.calf * math.sin(q2), -(g.thigh + g.calf * math.cos(q2))))
    return (q0, q1, q2)


def smoothstep(u: float) -> float:
    """(1 - cos(pi u)) / 2 on [0, 1], clamped: zero velocity at both ends."""
    u = min(max(u, 0.0), 1.0)
    return 0.5 - 0.5 * math.cos(math.pi * u)


@dataclass(frozen=True)
class Trot:
    """A trot: diagonal pairs (FR + RL, FL + RR) alternate, half a period each in stance."""

    period: float  #: one gait cycle [s]
    lift: float  #: swing foot clearance [m]

    #: phase offset of each leg in bus order FR, FL, RR, RL
    OFFSETS = (0.0, 0.5, 0.5, 0.0)

    def foot(self, leg: int, t: float, v_hip: tuple[float, float],
             height: float) -> tuple[float, float, float, bool]:
        """Foot (dx, dy, z) relative to its nominal point below the hip, and whether it is
        in stance, at gait time ``t`` for a hip moving at ``v_hip`` over the ground.

        In stance the foot moves backwards at exactly the hip's velocity (it stays put on the
        ground); in swing it goes from the stance end to the next stance start."""
        phase = (t / self.period + self.OFFSETS[leg]) % 1.0
        half = self.period / 2
        vx, vy = v_hip
        if phase < 0.5:
            ts = phase * self.period - half / 2
            return (-vx * ts, -vy * ts, -height, True)
        u = (phase - 0.5) * 2
        k = smoothstep(u) - 0.5
        return (vx * half * k, vy * half * k, -height + self.lift * math.sin(math.pi * u), False)
