"""The seed's messages: the generated classes, the checked route, the ROS envelope.

A route (:class:`Route`) is a GTraceList checked once on arrival: every point finite and on
the map (its extent, as move_base refuses an off-map goal), no segment shorter than
:data:`MIN_SEGMENT`, ``finished`` within 0..1, the map the module runs on (``map`` holds the
map's name, UTF-8; empty: whatever map the module runs on). A point's
``speed`` is in mm/s (int32); absent or <= 0 means the module's default speed.

On ROS every message travels as ``lowerbase_msgs/Protobuf``: ``type`` the protobuf message's
name (``"GTraceList"``), ``data`` its serialized bytes; :func:`decode` checks both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from google.protobuf.message import DecodeError, Message

from lowerbase.errors import LowerbaseError
from lowerbase.text import num, point
from lowerbase.trace.proto.trace_pb2 import (
    GLaserScan,
    GRobotSpeedControl,
    GTraceList,
    GTracePoint,
    GTraceSeg,
    RobotPose2D,
)

__all__ = ["GLaserScan", "GRobotSpeedControl", "GTraceList", "GTracePoint", "GTraceSeg",
           "RobotPose2D"]

IDLE = GTraceList.EXECUTE_STATUS_IDLE
RUNNING = GTraceList.EXECUTE_STATUS_RUNNING
BLOCKED = GTraceList.EXECUTE_STATUS_BLOCKED
FINISHED = GTraceList.EXECUTE_STATUS_FINISHED
STATUS_NAMES = {IDLE: "IDLE", RUNNING: "RUNNING", BLOCKED: "BLOCKED", FINISHED: "FINISHED"}

#: a segment shorter than this [m] has no direction: the list is refused
MIN_SEGMENT = 0.01
#: the protobuf types a ``lowerbase_msgs/Protobuf`` may carry, by ``type``
TYPES: dict[str, type[Message]] = {c.DESCRIPTOR.name: c for c in (
    GTraceList, GLaserScan, RobotPose2D, GRobotSpeedControl)}


class TraceError(LowerbaseError):
    """A message the navigation module refuses: undecodable, or a route it cannot drive."""


@dataclass(frozen=True)
class Segment:
    x0: float
    y0: float
    x1: float
    y1: float
    speed: float  #: [m/s], 0: the module's default
    starter: bool  #: its first point may start a trace

    @property
    def length(self) -> float:
        return math.hypot(self.x1 - self.x0, self.y1 - self.y0)

    @property
    def heading(self) -> float:
        return math.atan2(self.y1 - self.y0, self.x1 - self.x0)

    def point(self, t: float) -> tuple[float, float]:
        return self.x0 + t * (self.x1 - self.x0), self.y0 + t * (self.y1 - self.y0)

    def project(self, x: float, y: float) -> tuple[float, float]:
        """(along-track fraction, unclamped; signed cross-track [m], left > 0) of a point."""
        dx, dy = self.x1 - self.x0, self.y1 - self.y0
        n = self.length
        px, py = x - self.x0, y - self.y0
        return (px * dx + py * dy) / (n * n), (dx * py - dy * px) / n


@dataclass(frozen=True)
class Route:
    """A checked GTraceList: segments, their ``finished``, the final heading, the map."""

    segments: tuple[Segment, ...]
    finished: tuple[float, ...]
    final_angle: float
    map: bytes
    source: GTraceList  #: the list as received (reports copy it)


def _finite(value: float, what: str) -> float:
    if not math.isfinite(value):
        raise TraceError(f"{what} is {value}: every coordinate must be a finite number")
    return float(value)


#: (x_min, y_min, x_max, y_max) [m] of a map (``OccupancyGrid.extent``)
Extent = tuple[float, float, float, float]


def _on_map(x: float, y: float, extent: Extent | None, what: str) -> None:
    if extent is None:
        return
    x0, y0, x1, y1 = extent
    if not (x0 <= x < x1 and y0 <= y < y1):
        raise TraceError(f"{what} {point(x, y)} is off the map (x {num(x0)}..{num(x1)} m, "
                         f"y {num(y0)}..{num(y1)} m): send points on the map")


def check_route(msg: GTraceList, map_name: str = "", extent: Extent | None = None) -> Route:
    """The route of a non-empty GTraceList, or a :class:`TraceError` saying what is wrong.
    ``extent``: the map's area; a point outside it is refused (None: not checked)."""
    if msg.map and map_name and msg.map != map_name.encode():
        raise TraceError(f"the list is for map {msg.map!r}, this module runs on {map_name!r}")
    segs: list[Segment] = []
    done: list[float] = []
    for i, s in enumerate(msg.lists):
        a, b = s.first, s.second
        coords = [_finite(v, f"segment {i} {w}") for v, w in (
            (a.x, "first.x"), (a.y, "first.y"), (a.angle, "first.angle"), (b.x, "second.x"),
            (b.y, "second.y"), (b.angle, "second.angle"))]
        _on_map(coords[0], coords[1], extent, f"segment {i} first point")
        _on_map(coords[3], coords[4], extent, f"segment {i} second point")
        f = _finite(s.finished, f"segment {i} finished")
        if not 0.0 <= f <= 1.0:
            raise TraceError(f"segment {i} finished = {f}: it must lie within 0..1")
        seg = Segment(coords[0], coords[1], coords[3], coords[4],
                      max(a.speed, 0) / 1000.0 if a.HasField("speed") else 0.0,
                      a.HasField("starter") and a.starter != 0)
        if seg.length < MIN_SEGMENT:
            raise TraceError(f"segment {i} has length {seg.length:.4f} m (< {MIN_SEGMENT} m): "
                             "a segment needs two distinct points")
        segs.append(seg)
        done.append(f)
    if not segs:
        raise TraceError("the list has no segment")
    return Route(tuple(segs), tuple(done), float(msg.lists[-1].second.angle), bytes(msg.map),
                 msg)


def report(route: Route | GTraceList, status: int, finished: list[float] | None = None
           ) -> GTraceList:
    """The list to report: a copy of what was received, with ``finished`` and ``status``."""
    out = GTraceList()
    out.CopyFrom(route.source if isinstance(route, Route) else route)
    if finished is not None:
        for seg, f in zip(out.lists, finished, strict=True):
            seg.finished = f
    out.status = status  # type: ignore[assignment]
    return out


def encode(msg: Message) -> tuple[str, bytes]:
    """(type, data) of a ``lowerbase_msgs/Protobuf``."""
    return msg.DESCRIPTOR.name, msg.SerializeToString()


def decode(type_name: str, data: bytes, expected: type[Message]) -> Message:
    """The message in a ``lowerbase_msgs/Protobuf``; :class:`TraceError` if ``type`` is not
    ``expected``'s name or the bytes do not parse (a required field missing included)."""
    want = expected.DESCRIPTOR.name
    if type_name != want:
        raise TraceError(f"a {type_name!r} message on a {want} topic: send {want}")
    msg = expected()
    try:
        msg.ParseFromString(bytes(data))
    except DecodeError as exc:
        raise TraceError(f"an undecodable {want} ({len(data)} bytes): {exc}") from None
    if not msg.IsInitialized():
        missing = ", ".join(msg.FindInitializationErrors())
        raise TraceError(f"a {want} without its required field(s) {missing}: fill them in")
    return msg
