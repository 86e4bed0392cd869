"""A TF buffer for the faces of one ROS 2 process (:class:`TfBuffer`): what
``tf2_ros.Buffer`` does for navigation's :class:`~lowerbase.navigation.tf_map.MapToOdom`, on
the transforms the process' own broadcasters send (there is no tf2_ros wheel).

It keeps each parent -> child edge's transforms by stamp (``cache_time`` of them) and answers
lookups of one edge, as tf2 does for a direct parent -> child pair: the newest (``Stamp(0)``),
or linearly interpolated at a stamp (the rotation about z only: the robot's frames are
planar), and :class:`TransformException` outside the cache, as tf2's extrapolation error.
Chains of several edges are not looked up (nothing in lowerbase asks for one).
"""

from __future__ import annotations

import bisect
import copy
import math
from typing import Any


class TransformException(Exception):
    """No transform (yet) between the frames, or not at that stamp."""


def _sec(stamp: Any) -> float:
    """[s] of a Stamp or a builtin_interfaces/Time."""
    if hasattr(stamp, "ns"):
        return float(stamp.ns) / 1e9
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


class TfBuffer:
    """tf2_ros.Buffer's ``set_transform(_static)``, ``lookup_transform``,
    ``get_latest_common_time`` for direct edges (see the module docstring)."""

    TransformException = TransformException

    def __init__(self, cache_time: float = 10.0) -> None:
        self.cache_time = cache_time
        self._edges: dict[tuple[str, str], tuple[list[float], list[Any]]] = {}
        self._static: dict[tuple[str, str], Any] = {}

    def set_transform(self, t: Any, authority: str = "") -> None:
        key = (t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/"))
        times, items = self._edges.setdefault(key, ([], []))
        at = _sec(t.header.stamp)
        i = bisect.bisect_right(times, at)
        times.insert(i, at)
        items.insert(i, t)
        while times and times[-1] - times[0] > self.cache_time:
            del times[0], items[0]

    def set_transform_static(self, t: Any, authority: str = "") -> None:
        self._static[(t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/"))] = t

    def lookup_transform(self, target: str, source: str, stamp: Any) -> Any:
        key = (target.lstrip("/"), source.lstrip("/"))
        if key in self._static:
            return self._static[key]
        times, items = self._edges.get(key, ([], []))
        if not times:
            raise TransformException(f"no transform {key[0]} -> {key[1]}")
        at = _sec(stamp)
        if at == 0.0:
            return items[-1]
        if not times[0] - 1e-9 <= at <= times[-1] + 1e-9:
            raise TransformException(f"{key[0]} -> {key[1]} at {at:.3f} s: outside "
                                     f"[{times[0]:.3f}, {times[-1]:.3f}]")
        i = max(0, bisect.bisect_right(times, at + 1e-9) - 1)  # the last at or before
        if i >= len(times) - 1 or abs(times[i] - at) <= 1e-9:
            return items[i]
        return _interpolate(items[i], items[i + 1], (at - times[i]) / (times[i + 1] - times[i]))

    def get_latest_common_time(self, target: str, source: str) -> Any:
        """The newest stamp of the edge (its ``to_sec()``: [s])."""
        key = (target.lstrip("/"), source.lstrip("/"))
        times = self._edges.get(key, ([], []))[0]
        if not times:
            raise TransformException(f"no transform {key[0]} -> {key[1]}")
        return _Seconds(times[-1])


class _Seconds(float):
    """A stamp [s] as rospy's Time reads it (``to_sec``)."""

    def to_sec(self) -> float:
        return float(self)


def _interpolate(a: Any, b: Any, f: float) -> Any:
    out = copy.deepcopy(a)
    ta, tb, to = a.transform.translation, b.transform.translation, out.transform.translation
    to.x, to.y, to.z = (ta.x + f * (tb.x - ta.x), ta.y + f * (tb.y - ta.y),
                        ta.z + f * (tb.z - ta.z))
    ya, yb = _yaw(a.transform.rotation), _yaw(b.transform.rotation)
    yaw = ya + f * math.atan2(math.sin(yb - ya), math.cos(yb - ya))
    r = out.transform.rotation
    r.x, r.y, r.z, r.w = 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)
    return out
