"""legged_driver: the legged robot's ROS1 node, a thin rospy layer over LeggedDriverCore.

The seed's interface (shared/seeds/003, package ``lowerbase_legged_msgs``), names relative so
that they sit at the root with no namespace: ``robot_state`` (published at ``~publish_rate``),
``planning/set_waypoints``, ``planning/get_waypoints``, ``planning/append_waypoint``,
``set_map``, ``set_listen``; subscribed: ``/cmd_vel`` (geometry_msgs/Twist: linear.x, linear.y,
angular.z; the seed names no velocity topic) and the sensor_msgs/Joy topic handed over by
set_listen. The seed has no call that brings the robot to walking state: ``~walk``, ``~stand``
and ``~sit`` (std_srvs/Trigger) send the LocomotionRequests that lead there along the state
table (:mod:`lowerbase.legged_driver.goals`). Nor does it have one that ends a waypoint
mission (an empty list is refused): ``~stop_waypoints`` (std_srvs/Trigger) does, an endless one
too.

Threads (one lock around every core call): a reader per leg bus (four BusLinks, each reopened
every second after an error), the main loop (tick: BodyVelocityCommand, locomotion goal,
robot_state), rospy's callback threads. ``lowerbase driver --robot legged`` runs it.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from lowerbase.clock import RealClock
from lowerbase.errors import ConfigError, RosUnavailableError
from lowerbase.legged.runner import leg_bus_configs  # the emulator's convention, one copy
from lowerbase.legged_driver.core import LeggedDriverConfig, LeggedDriverCore
from lowerbase.legged_driver.goals import GoalPursuit
from lowerbase.legged_driver.waypoints import TIMEOUT, GpsDatum, Waypoint
from lowerbase.protocol.legged import LocomotionState, legged_codec

log = logging.getLogger(__name__)

NODE_NAME = "legged_driver"
PACKAGE = "lowerbase_legged_msgs"
S = LocomotionState

#: topic keys -> default names (relative: the node's namespace, the root by default)
DEFAULT_TOPICS = {"robot_state": "robot_state", "cmd_vel": "/cmd_vel"}
#: service keys -> the seed's names
SERVICES = {"set_waypoints": "planning/set_waypoints", "get_waypoints": "planning/get_waypoints",
            "append_waypoint": "planning/append_waypoint", "set_map": "set_map",
            "set_listen": "set_listen"}
#: ~walk / ~stand / ~sit: the state each brings the robot to
GOALS = {"walk": S.IN_CONTROL, "stand": S.STANDING_MODE, "sit": S.SITDOWN_MODE}


# -- settings (pure) ----------------------------------------------------------------------------


@dataclass(frozen=True)
class LeggedSettings:
    topics: dict[str, str] = field(default_factory=lambda: dict(DEFAULT_TOPICS))
    services: dict[str, str] = field(default_factory=lambda: dict(SERVICES))
    publish_rate: float = 50.0  # Hz: robot_state
    request_retry: float = 0.25  # s: a LocomotionRequest is repeated until the state moves


def _number(name: str, value: Any, low: float = 0.0) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and value > low):
        raise ConfigError(f"~{name} must be a number > {low:g}, got {value!r}")
    return float(value)


def _names(kind: str, defaults: Mapping[str, str], given: Any) -> dict[str, str]:
    if given is None:
        return dict(defaults)
    if not isinstance(given, Mapping) or set(given) - set(defaults):
        raise ConfigError(f"~{kind} must be a dictionary with keys among {', '.join(defaults)}, "
                          f"got {given!r}")
    out = {**defaults, **given}
    for key, name in out.items():
        if not isinstance(name, str) or (kind == "services" and not name):
            raise ConfigError(f"~{kind}/{key} must be a name, got {name!r}")
    return out


def gps_datum(value: Any) -> GpsDatum | None:
    """~gps_origin: [latitude, longitude] with optional altitude [m] and heading of odom's x
    axis [rad, counterclockwise from east]; None or [] for no origin (gps waypoints refused)."""
    if value is None or value == [] or value == "":
        return None
    if not isinstance(value, (list, tuple)) or not 2 <= len(value) <= 4 or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise ConfigError(f"~gps_origin must be [latitude, longitude, altitude, heading] "
                          f"(the last two optional), got {value!r}")
    try:
        return GpsDatum(*(float(v) for v in value))
    except ValueError as exc:
        raise ConfigError(f"~gps_origin: {exc}") from None


def load_legged_settings(params: Mapping[str, Any], ros_home: Path | None = None
                         ) -> tuple[LeggedSettings, LeggedDriverConfig]:
    """Node settings and core configuration from the node's private parameters."""
    known = {"topics", "services", "publish_rate", "request_retry", "command_rate",
             "gps_origin", "mapping_plugin", "map_dir", "listen_velocity"}
    unknown = sorted(set(params) - known)
    if unknown:
        raise ConfigError(f"unknown parameter(s) ~{', ~'.join(unknown)}; known: "
                          f"~{', ~'.join(sorted(known))} (docs/legged.md)")
    for name in ("mapping_plugin", "listen_velocity"):
        if not isinstance(params.get(name, True), bool):
            raise ConfigError(f"~{name} must be true or false, got {params[name]!r}")
    map_dir = params.get("map_dir", "")
    if not isinstance(map_dir, str):
        raise ConfigError(f"~map_dir must be a directory name, got {map_dir!r}")
    home = ros_home or Path(os.environ.get("ROS_HOME", Path.home() / ".ros"))
    settings = LeggedSettings(
        topics=_names("topics", DEFAULT_TOPICS, params.get("topics")),
        services=_names("services", SERVICES, params.get("services")),
        publish_rate=_number("publish_rate", params.get("publish_rate", 50.0)),
        request_retry=_number("request_retry", params.get("request_retry", 0.25)))
    config = LeggedDriverConfig(
        command_rate=_number("command_rate", params.get("command_rate", 50.0)),
        gps_datum=gps_datum(params.get("gps_origin")),
        mapping_plugin=params.get("mapping_plugin", True),
        map_dir=Path(map_dir).expanduser() if map_dir else home / "maps",
        listen_velocity=params.get("listen_velocity", True))
    return settings, config


def lower_ids() -> list[int]:
    """The IDs the driver reads: what the actuators and the body controller send."""
    return sorted(m.frame_id for m in legged_codec()
                  if "Upper" not in m.senders and {"Body", "Actuator"} & set(m.senders))


# -- ROS ----------------------------------------------------------------------------------------


def import_ros() -> SimpleNamespace:
    """rospy and the message modules; RosUnavailableError with one clear line if missing."""
    try:
        import rospy
        from geometry_msgs.msg import Twist
        from sensor_msgs.msg import Joy
        from std_srvs.srv import Trigger, TriggerResponse  # type: ignore[import-untyped]
    except ImportError as exc:
        raise RosUnavailableError(
            f"ROS is not installed ({exc}): run lowerbase from a venv made from the ROS Python "
            "(/usr/bin/python3 -m venv --system-site-packages VENV) or source "
            "/opt/ros/noetic/setup.bash; docs/driver.md") from None
    try:
        from lowerbase_legged_msgs import msg, srv
    except ImportError:
        raise RosUnavailableError(
            f"{PACKAGE} is not generated for {sys.executable}: run "
            f"{Path(sys.executable).name} -m lowerbase.driver.msggen") from None
    return SimpleNamespace(rospy=rospy, Twist=Twist, Joy=Joy, Trigger=Trigger,
                           TriggerResponse=TriggerResponse, msg=msg, srv=srv)


class LeggedNode:
    """Publisher, subscribers, services and the tick loop around one LeggedDriverCore."""

    def __init__(self, settings: LeggedSettings, config: LeggedDriverConfig,
                 links: Sequence[Any], *, core: LeggedDriverCore | None = None,
                 wire: Any = None, lock: Any = None, ros: Any = None) -> None:
        """``core``: a LeggedDriverCore that already talks to its lower computer (the lockstep
        robot's; ``links`` are then unused); ``wire``: how the face reaches ROS
        (:mod:`lowerbase.ros1.wire`; None: rospy as is); ``lock``: shared with the loop;
        ``ros``: :func:`import_ros`'s namespace (None: ROS 1's; ROS 2's is
        :func:`lowerbase.ros2.compat.legged_ros`)."""
        from lowerbase.ros1.wire import RosWire

        self.ros = ros if ros is not None else import_ros()
        self.wire = wire if wire is not None else RosWire(self.ros.rospy)
        self.settings, self.links = settings, links
        self.lock = lock if lock is not None else threading.RLock()
        self.stop = threading.Event()
        self.core = core if core is not None else \
            LeggedDriverCore(self._send, RealClock(self.stop), config)
        self.goals = GoalPursuit(settings.request_retry)
        self._joy_sub: Any = None
        self._joy_topic: str | None = None
        self._handles: list[Any] = []
        self._readers: list[threading.Thread] = []

    def _send(self, bus: int, frame_id: int, data: bytes) -> None:
        self.links[bus].send(frame_id, data)

    def advertise(self) -> None:
        ros, s, wire = self.ros, self.settings, self.wire
        srv = ros.srv
        self._state_pub = wire.publisher(s.topics["robot_state"], ros.msg.RobotState,
                                         queue_size=5)
        if s.topics["cmd_vel"]:
            self._handles.append(wire.subscriber(s.topics["cmd_vel"], ros.Twist,
                                                 self._on_twist, queue_size=10, external=True))
        handlers: dict[str, tuple[Any, Callable[[Any], Any]]] = {
            "set_waypoints": (srv.SetWaypoints, self._set_waypoints),
            "get_waypoints": (srv.GetWaypoints, self._get_waypoints),
            "append_waypoint": (srv.AppendWaypoint, self._append_waypoint),
            "set_map": (srv.SetLaserMap, self._set_map),
            "set_listen": (srv.SetListen, self._set_listen)}
        for key, (cls, handler) in handlers.items():
            self._handles.append(wire.service(s.services[key], cls, handler))
        for name, goal in GOALS.items():
            self._handles.append(wire.service(f"~{name}", ros.Trigger, self._goal_handler(goal)))
        self._handles.append(wire.service("~stop_waypoints", ros.Trigger, self._stop_waypoints))

    def _goal_handler(self, goal: LocomotionState) -> Callable[[Any], Any]:
        return lambda _req: self._set_goal(goal)

    # -- ROS -> core ----------------------------------------------------------------------------

    def _on_twist(self, msg: Any) -> None:
        with self.lock:
            self.core.set_velocity(msg.linear.x, msg.linear.y, msg.angular.z)

    def _on_joy(self, msg: Any, topic: str) -> None:
        with self.lock:
            self.core.on_joy(topic, list(msg.axes))

    @staticmethod
    def _waypoint(w: Any) -> Waypoint:
        return Waypoint(w.frame, w.x, w.y, w.z, bool(w.use_z))

    def _set_waypoints(self, req: Any) -> Any:
        with self.lock:
            ok, message = self.core.set_waypoints([self._waypoint(w) for w in req.waypoints],
                                                  req.repetition, req.current_index)
        return self.ros.srv.SetWaypointsResponse(success=ok, message=message)

    def _get_waypoints(self, req: Any) -> Any:
        with self.lock:
            ok, message, wps, laps, index = self.core.get_waypoints()
        Wp = self.ros.msg.Waypoint
        return self.ros.srv.GetWaypointsResponse(
            success=ok, message=message, repetition=min(laps, 255), current_index=min(index, 255),
            waypoints=[Wp(frame=w.frame, x=w.x, y=w.y, z=w.z, use_z=w.use_z) for w in wps])

    def _append_waypoint(self, req: Any) -> Any:
        with self.lock:
            ok, message = self.core.append_waypoint(self._waypoint(req.waypoint))
        return self.ros.srv.AppendWaypointResponse(success=ok, message=message)

    def _stop_waypoints(self, req: Any) -> Any:
        with self.lock:
            ok, message = self.core.stop_waypoints()
        return self.ros.TriggerResponse(success=ok, message=message)

    def _set_map(self, req: Any) -> Any:
        p, q = req.initial_pose.position, req.initial_pose.orientation
        with self.lock:
            ok, message = self.core.set_map(req.name, req.pc, (p.x, p.y, p.z, q.x, q.y, q.z, q.w))
        return self.ros.srv.SetLaserMapResponse(success=ok, message=message)

    def _set_listen(self, req: Any) -> Any:
        with self.lock:
            ok, message = self.core.set_listen(req.data)
            holder = self.core.joystick.holder
            topic = holder.topic if holder is not None else None
            if topic != self._joy_topic:
                if self._joy_sub is not None:
                    self._joy_sub.unregister()
                self._joy_sub, self._joy_topic = None, topic
                if topic is not None:
                    self._joy_sub = self.wire.subscriber(
                        topic, self.ros.Joy, functools.partial(self._on_joy, topic=topic),
                        queue_size=10, external=True)
        return self.ros.srv.SetListenResponse(success=ok, message=message)

    def _set_goal(self, goal: LocomotionState) -> Any:
        with self.lock:
            if not self.core.link_up:
                return self.ros.TriggerResponse(success=False, message=TIMEOUT)
            state = self.core.state
            self.goals.set(goal)
        return self.ros.TriggerResponse(success=True, message=f"{state.name} -> {goal.name}")

    # -- the loop -------------------------------------------------------------------------------

    @property
    def goal(self) -> LocomotionState | None:
        """The locomotion goal being pursued (None: none)."""
        return self.goals.goal

    def pursue_goal(self) -> None:
        """Send the next LocomotionRequest toward the goal (on a state change or every
        ``request_retry``); drop the goal once reached or when a fault is latched."""
        dropped = self.goals.pursue(self.core)
        if dropped is not None:
            log.warning("locomotion goal %s dropped: fault 0x%x", dropped.name, self.core.fault)

    def publish_state(self) -> None:
        """robot_state, now."""
        self._state_pub.publish(self.robot_state_msg())

    def robot_state_msg(self) -> Any:
        msg = self.ros.msg
        st = self.core.robot_state()
        acts = [msg.ActuatorState(**a) for a in st.pop("actuator_states")]  # type: ignore[attr-defined]
        return msg.RobotState(actuator_states=acts, **st)

    def start_readers(self) -> None:
        for bus, link in enumerate(self.links):
            def on_frame(frame_id: int, data: bytes, bus: int = bus) -> None:
                with self.lock:
                    self.core.on_frame(bus, frame_id, data)

            t = threading.Thread(target=link.run_reader, args=(on_frame, self.stop),
                                 name=f"legged-reader-{bus}", daemon=True)
            t.start()
            self._readers.append(t)

    def spin(self) -> None:
        rospy = self.ros.rospy
        rospy.on_shutdown(self.stop.set)
        period = 1.0 / self.core.config.command_rate
        publish_every = 1.0 / self.settings.publish_rate
        deadline, next_publish = time.monotonic(), 0.0
        while not self.stop.is_set() and not rospy.is_shutdown():
            with self.lock:
                self.pursue_goal()
                self.core.tick()
                now = time.monotonic()
                if now >= next_publish:
                    next_publish = max(next_publish + publish_every, now - publish_every)
                    self.publish_state()
            deadline += period
            delay = deadline - time.monotonic()
            if delay < -1.0:
                deadline = time.monotonic()
            self.stop.wait(max(delay, 0.0))

    def shutdown(self) -> None:
        self.stop.set()
        for t in self._readers:
            t.join(timeout=3.0)
        with self.lock:
            if self._joy_topic:
                self.core.set_listen(f"{self._joy_topic}<&><CLOSE>")
            self.core.set_velocity(0.0, 0.0, 0.0)
            self.core.follower.set([], 1, 0)
            self.core.tick()  # one stop on the body bus
        for handle in [*self._handles, self._joy_sub]:
            if handle is not None:
                with contextlib.suppress(Exception):
                    (handle.unregister if hasattr(handle, "unregister") else handle.shutdown)()
        for link in self.links:
            link.close()



def make_map_dir(config: LeggedDriverConfig) -> None:
    """Make set_map's directory (``~map_dir``) if it is set; a ConfigError line if it cannot
    be made."""
    if config.map_dir is not None:
        try:
            config.map_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(f"~map_dir {config.map_dir}: {exc.strerror}") from None

def run(bus_config: dict[str, Any], ros_args: Sequence[str], *, name: str = NODE_NAME,
        params: dict[str, Any] | None = None) -> int:
    """Open the four leg buses, start rospy and spin until shutdown."""
    from lowerbase.driver.links import FULL_ID_MASK, BusLink
    from lowerbase.ros1.node import ros_session

    import_ros()  # one line if ROS or the legged messages are missing
    configs = leg_bus_configs(bus_config)
    with contextlib.suppress(AttributeError, ValueError):
        sys.stdout.reconfigure(line_buffering=True)  # type: ignore[union-attr]
    filters = [{"can_id": i, "can_mask": FULL_ID_MASK} for i in lower_ids()]
    links: list[Any] = []
    with ros_session("driver", name, ros_args) as session:
        if session.loopback is not None:
            print(f"lowerbase driver: listening on loopback only (ROS_IP={session.loopback}); "
                  "set ROS_IP or ROS_HOSTNAME to this host's address to serve other hosts",
                  flush=True)
        try:
            for cfg in configs:
                links.append(BusLink({**cfg, "can_filters": filters}))
            settings, config = load_legged_settings(
                {**session.rospy.get_param("~", {}), **(params or {})})
            make_map_dir(config)
            node = LeggedNode(settings, config, links)
            node.advertise()
            node.start_readers()
            where = ", ".join(f"{c.get('interface')} {c.get('channel')}"
                              + (f":{c['port']}" if "port" in c else "") for c in configs)
            session.announce(f"legged, buses {where}")
            try:
                node.spin()
            finally:
                node.shutdown()
                session.stopped(node.core.stats)
        finally:
            for link in links:
                link.close()
    return 0
