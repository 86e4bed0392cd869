"""remaining() sums segment lengths computed once per path: bit for bit the per-call sum over
the sliced path it replaced, for every index, and recomputed when the plan changes."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from lowerbase.navigation.goals import Pose, remaining


def remaining_per_call(path: Sequence[Pose], index: int, p: Pose, approach: float) -> float:
    """The function before the segment lengths were kept (lowerbase before this change)."""
    if not path:
        return 0.0
    gx, gy, _ = path[-1]
    straight = math.hypot(gx - p[0], gy - p[1])
    rest = np.asarray(path[index:])[:, :2]
    if not len(rest) or straight <= approach:
        return straight
    along = float(np.hypot(*np.diff(rest, axis=0).T).sum()) if len(rest) > 1 else 0.0
    return math.hypot(rest[0, 0] - p[0], rest[0, 1] - p[1]) + along


def random_path(rng: np.random.Generator, n: int) -> list[Pose]:
    xy = np.cumsum(rng.normal(0.05, 0.03, (n, 2)), axis=0)
    return [(float(x), float(y), float(a)) for (x, y), a in zip(xy, rng.uniform(-3, 3, n),
                                                              strict=True)]


def test_remaining_equals_the_per_call_sum_for_every_index_and_plan() -> None:
    rng = np.random.default_rng(5)
    for n in (1, 2, 9, 300, 1000):
        path = random_path(rng, n)
        p = (path[0][0] + 0.03, path[0][1] - 0.02, 0.0)
        for index in sorted(i for i in {0, 1, n // 3, n - 2, n - 1} if 0 <= i < n):
            for approach in (0.0, 0.6, 1e9):
                assert remaining(path, index, p, approach) == \
                    remaining_per_call(path, index, p, approach)
        # past the end (the old sum raised IndexError there): straight to the goal
        straight = math.hypot(path[-1][0] - p[0], path[-1][1] - p[1])
        assert remaining(path, n, p, 0.0) == straight
    # a new plan of the same length, and the same list object edited: not the old lengths
    a = random_path(rng, 50)
    b = random_path(rng, 50)
    p = (0.0, 0.0, 0.0)
    assert remaining(a, 3, p, 0.0) == remaining_per_call(a, 3, p, 0.0)
    assert remaining(b, 3, p, 0.0) == remaining_per_call(b, 3, p, 0.0)
    b[-1] = (b[-1][0] + 1.0, b[-1][1], 0.0)
    assert remaining(b, 3, p, 0.0) == remaining_per_call(b, 3, p, 0.0)
    assert remaining([], 0, p, 0.0) == 0.0
