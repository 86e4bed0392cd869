"""Routes and worlds for the trace tests: the warehouse's bottom corridor (y 0.15..3.0 m)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

from lowerbase.trace import messages as m
from lowerbase.trace.base import TraceParams
from lowerbase.trace.sim import TraceSim
from lowerbase.world.obstacles import obstacles_from_dicts
from lowerbase.world.sim import WorldConfig

Y = 1.2  #: the route's line
CRATE = {"kind": "box", "name": "crate", "center": [13.0, Y], "size": [0.4, 0.4]}


def route(xs: Sequence[float], y: float = Y, starters: Sequence[int] = (), speed: int = 0,
          finished: Sequence[float] = (), final_angle: float = 0.0) -> m.GTraceList:
    lst = m.GTraceList(map=b"warehouse")
    for i, (a, b) in enumerate(itertools.pairwise(xs)):
        s = lst.lists.add()
        s.first.x, s.first.y, s.first.angle = a, y, 0.0
        s.second.x, s.second.y = b, y
        s.second.angle = final_angle if i == len(xs) - 2 else 0.0
        s.finished = finished[i] if finished else 0.0
        if i in starters:
            s.first.starter = 1
        if speed:
            s.first.speed = speed
    return lst


def trace_sim(start_x: float = 6.0, crate: bool = False, localization: str = "truth",
              **params: float) -> TraceSim:
    obstacles = obstacles_from_dicts([CRATE] if crate else [])
    return TraceSim(WorldConfig(map="warehouse", start=(start_x, Y, 0.0),
                                localization=localization, obstacles=obstacles),
                    TraceParams(map_name="warehouse", **params))  # type: ignore[arg-type]
