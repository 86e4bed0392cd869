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
from lowerbase.trace.obstacle_navigate import ObstacleNavigate
from lowerbase.trace.trace_navigate import TraceNavigate
from lowerbase.world.sim import WorldConfig, WorldSim

ROUTE, STATUS = "msg_trace_navigate_route", "msg_trace_navigate_status"
AVOID_ROUTE, AVOID_STATUS = "msg_obstacle_navigate_route", "msg_obstacle_navigate_status"
LASER, POSE, SPEED = "msg_robot_laser_data", "msg_robot_global_pos", "msg_robot_speed_control"
TOPICS = (ROUTE, STATUS, AVOID_ROUTE, AVOID_STATUS, LASER, POSE, SPEED)
#: the message type on each topic
TOPIC_TYPES: dict[str, type[Message]] = {
    ROUTE: m.GTraceList, STATUS: m.GTraceList, AVOID_ROUTE: m.GTraceList,
    AVOID_STATUS: m.GTraceList, LASER: m.GLaserScan, POSE: m.RobotPose2D,
    SPEED: m.GRobotSpeedControl}

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
        self.trace = TraceNavigate(clock, lambda msg: self.publish(STATUS, msg),
                                   lambda msg: self.publish(SPEED, msg), self.params,
                                   limits=limits, footprint=self.world.config.footprint)
        self.obstacle = ObstacleNavigate(clock, self.world.grid,
                                         lambda msg: self.publish(AVOID_STATUS, msg),
                                         lambda msg: self.publish(SPEED, msg), self.params,
                                         limits=limits, footprint=self.world.config.footprint)
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
        type_name, data = m.encode(msg)
        received = m.decode(type_name, data, TOPIC_TYPES[topic])
        self.published[topic].append((self.now, received))
        if topic == ROUTE:
            self.trace.on_route(received)
        elif topic == AVOID_ROUTE:
            self.obstacle.on_route(received)
        elif topic == SPEED:
            self.speed_bridge(received)
        elif topic == LASER:
            self.trace.on_scan(received)
            self.obstacle.on_scan(received)
        elif topic == POSE:
            self.trace.on_pose(received)
            self.obstacle.on_pose(received)
        elif topic in (STATUS, AVOID_STATUS):
            for listener in list(self.listeners):
                listener(topic, received)

    def step(self) -> None:
        """One control period of the chassis; the modules tick at their period."""
        self.world.step()
        self._steps += 1
        if self._steps % self._every:
            return
        self._bridge(laser=self._steps % self._laser_every == 0)
        self.trace.tick()
        self.obstacle.tick()

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
