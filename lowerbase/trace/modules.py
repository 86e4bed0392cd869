"""Both modules behind the seed's topics, ROS-free: what a node (or TraceSim) wires.

:class:`TraceModules` holds TraceNavigate and ObstacleNavigate and takes every incoming message
as the ``lowerbase_msgs/Protobuf`` envelope carries it (``type``, ``data``): :meth:`receive`
decodes it for its topic and hands it on; a wrong ``type``, bytes that do not parse or a
required field missing is dropped, counted in ``dropped[topic]`` and logged (the first one per
topic), never raised. What the modules publish goes to ``send(topic, message)``.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable

from google.protobuf.message import Message

from lowerbase.clock import Clock
from lowerbase.navigation.controller import Limits
from lowerbase.trace import messages as m
from lowerbase.trace.base import Navigator, TraceParams
from lowerbase.trace.obstacle_navigate import ObstacleNavigate
from lowerbase.trace.trace_navigate import TraceNavigate
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, Footprint
from lowerbase.world.grid import OccupancyGrid

log = logging.getLogger(__name__)

ROUTE, STATUS = "msg_trace_navigate_route", "msg_trace_navigate_status"
AVOID_ROUTE, AVOID_STATUS = "msg_obstacle_navigate_route", "msg_obstacle_navigate_status"
LASER, POSE, SPEED = "msg_robot_laser_data", "msg_robot_global_pos", "msg_robot_speed_control"
TOPICS = (ROUTE, STATUS, AVOID_ROUTE, AVOID_STATUS, LASER, POSE, SPEED)
#: the message type on each topic
TOPIC_TYPES: dict[str, type[Message]] = {
    ROUTE: m.GTraceList, STATUS: m.GTraceList, AVOID_ROUTE: m.GTraceList,
    AVOID_STATUS: m.GTraceList, LASER: m.GLaserScan, POSE: m.RobotPose2D,
    SPEED: m.GRobotSpeedControl}
#: the topics the modules subscribe
INPUTS = (ROUTE, AVOID_ROUTE, LASER, POSE)

Send = Callable[[str, Message], None]


class TraceModules:
    """TraceNavigate + ObstacleNavigate on one clock (see the module docstring)."""

    def __init__(self, clock: Clock, grid: OccupancyGrid, send: Send,
                 params: TraceParams | None = None, *, limits: Limits | None = None,
                 footprint: Footprint = DEFAULT_FOOTPRINT) -> None:
        self.params = params or TraceParams()
        self.dropped: Counter[str] = Counter()
        self.trace = TraceNavigate(clock, lambda msg: send(STATUS, msg),
                                   lambda msg: send(SPEED, msg), self.params, limits=limits,
                                   footprint=footprint, extent=grid.extent)
        self.obstacle = ObstacleNavigate(clock, grid, lambda msg: send(AVOID_STATUS, msg),
                                         lambda msg: send(SPEED, msg), self.params,
                                         limits=limits, footprint=footprint)

    @property
    def modules(self) -> tuple[Navigator, Navigator]:
        return self.trace, self.obstacle

    def decode(self, topic: str, type_name: str, data: bytes) -> Message | None:
        """The message of an envelope on ``topic``, or None (dropped, counted, logged)."""
        try:
            return m.decode(type_name, data, TOPIC_TYPES[topic])
        except m.TraceError as exc:
            self.dropped[topic] += 1
            if self.dropped[topic] == 1:
                log.warning("%s: dropped a message: %s (further drops are only counted)",
                            topic, exc)
            return None

    def receive(self, topic: str, type_name: str, data: bytes) -> bool:
        """One envelope on an input topic; False if it was dropped."""
        msg = self.decode(topic, type_name, data)
        if msg is None:
            return False
        self.deliver(topic, msg)
        return True

    def deliver(self, topic: str, msg: Message) -> None:
        """A decoded message on an input topic to the module(s) that subscribe it."""
        if topic == ROUTE:
            self.trace.on_route(msg)
        elif topic == AVOID_ROUTE:
            self.obstacle.on_route(msg)
        elif topic == LASER:
            for nav in self.modules:
                nav.on_scan(msg)
        elif topic == POSE:
            for nav in self.modules:
                nav.on_pose(msg)
        else:
            raise ValueError(f"{topic} is not an input of the trace modules")

    def tick(self) -> None:
        for nav in self.modules:
            nav.tick()

    def set_limits(self, limits: Limits) -> None:
        """The chassis' speed/acceleration limits (driver_base's parameters)."""
        for nav in self.modules:
            nav.limits = limits
            nav.ctl.limits = limits

    def stats(self) -> dict[str, int]:
        out = {f"dropped {t}": n for t, n in sorted(self.dropped.items())}
        for nav in self.modules:
            out |= {f"{nav.name} {k}": v for k, v in sorted(nav.stats.items())}
        return out
