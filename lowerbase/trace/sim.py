"""TraceSim: both modules beside the emulated chassis on the simulated clock, ROS-free.

A :class:`~lowerbase.world.sim.WorldSim` (emulator + driver_base core + map, obstacles, lidar,
localization) with TraceNavigate and ObstacleNavigate wired as the node wires them: every
message crosses as serialized bytes (the ``lowerbase_msgs/Protobuf`` envelope's ``type`` and
``data``), the bridges feed msg_robot_laser_data (each new /scan) and msg_robot_global_pos
(movebase_pose2d every control period), and msg_robot_speed_control reaches driver_base's
set_twist, whose frames drive the emulator. ``published[topic]`` keeps (time, message) of
every message on every topic; a business node is a callable given each status message.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable

from google.protobuf.message import Message

from lowerbase.navigation.controller import Limits
from lowerbase.trace import messages as m
from lowerbase.trace.base import TraceParams
from lowerbase.trace.bridges import SpeedBridge, laser_to_pb, pose_to_pb
from lowerbase.trace.modules import (
    AVOID_ROUTE,
    AVOID_STATUS,
    INPUTS,
    LASER,
    POSE,
    ROUTE,
    SPEED,
    STATUS,
    TOPIC_TYPES,
    TOPICS,
    TraceModules,
)
from lowerbase.world.sim import WorldConfig, WorldSim

__all__ = ["AVOID_ROUTE", "AVOID_STATUS", "LASER", "POSE", "ROUTE", "SPEED", "STATUS",
           "TOPICS", "TOPIC_TYPES", "TraceSim"]

Listener = Callable[[str, m.GTraceList], None]


class TraceSim:
    """See the module docstring. ``world`` is built from ``config`` unless given."""

    def __init__(self, config: WorldConfig | None = None, params: TraceParams | None = None,
                 *, world: WorldSim | None = None, settle: float = 1.0,
                 laser_period: float = 0.1) -> None:
        self.world = world if world is not None else WorldSim(config)
        self.world.run(settle)  # driver_base configured, odometry and localization running
        map_ref = self.world.config.map
        name = map_ref if isinstance(map_ref, str) else ""
        self.params = params or TraceParams(map_name=name)
        clock = self.world.loop.clock
        limits = Limits.from_parameters(self.world.loop.driver.parameters)
        self.published: dict[str, list[tuple[float, Message]]] = defaultdict(list)
        self.listeners: list[Listener] = []
        self.speed_bridge = SpeedBridge(self.world.loop.driver)
        self.modules = TraceModules(clock, self.world.grid, self.publish, self.params,
                                    limits=limits, footprint=self.world.config.footprint)
        self.trace, self.obstacle = self.modules.trace, self.modules.obstacle
        self._every = max(1, round(self.params.period / self.world.control_dt))
        #: msg_robot_laser_data's period [s] (the rig's newest scan at that rate)
        self._laser_every = max(1, round(laser_period / self.world.control_dt))
        self._steps = 0
        self._scan_stamp: float | None = None
        self._bridge(laser=True)  # the bridges have published before any list arrives

    @property
    def now(self) -> float:
        return self.world.now

    def publish(self, topic: str, msg: Message) -> None:
        """One message on a topic: through the wire format to whoever subscribes."""
        self.publish_raw(topic, *m.encode(msg))

    def publish_raw(self, topic: str, type_name: str, data: bytes) -> None:
        """An envelope (``type``, ``data``) as received from the wire: a bad one is dropped
        and counted in ``modules.dropped``."""
        received = self.modules.decode(topic, type_name, data)
        if received is None:
            return
        self.published[topic].append((self.now, received))
        if topic in INPUTS:
            self.modules.deliver(topic, received)
        elif topic == SPEED:
            self.speed_bridge(received)
        else:
            for listener in list(self.listeners):
                listener(topic, received)

    def step(self) -> None:
        """One control period of the chassis; the modules tick at their period."""
        self.world.step()
        self._steps += 1
        if self._steps % self._every:
            return
        self._bridge(laser=self._steps % self._laser_every == 0)
        self.modules.tick()

    def _bridge(self, laser: bool) -> None:
        pose = self.world.amcl_pose()
        if pose is not None:
            self.publish(POSE, pose_to_pb(pose, self.now))
        scan = self.world.scan if laser else None
        if scan is not None and scan.stamp != self._scan_stamp:
            self._scan_stamp = scan.stamp
            self.publish(LASER, laser_to_pb(scan))

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / self.world.control_dt)):
            self.step()

    def run_until(self, condition: Callable[[], bool], timeout: float) -> bool:
        end = self.now + timeout
        while self.now < end:
            if condition():
                return True
            self.step()
        return condition()

    def statuses(self, topic: str = STATUS) -> list[tuple[float, int]]:
        """(time, status) of every report on a status topic."""
        return [(t, msg.status) for t, msg in self.published[topic]]
