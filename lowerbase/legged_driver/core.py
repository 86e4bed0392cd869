"""The legged robot's upper-computer driver, ROS-free: lower-computer frames -> robot_state,
the seed's services (waypoints, set_map, set_listen) -> body velocity commands on the bus.

:class:`LeggedDriverCore` runs on an injected :class:`~lowerbase.clock.Clock` and a ``send(bus,
frame_id, data)`` callable, like the wheeled :class:`~lowerbase.driver.core.DriverCore`; the
rospy node (:mod:`lowerbase.legged_driver.node`) and the tests drive it the same way. Frames
come from four leg buses (``lowerbase.protocol.legged``): MotorReply on every leg bus, the body
frames on ``BODY_BUS``. A malformed frame or a body frame on the wrong bus is counted and dropped.
:meth:`LeggedDriverCore.on_frames` takes a period's frames at once (the simulated loop's 24
actuator frames per ms), decoded in compiled code (:mod:`.reply_kernel`), with the same result
as :meth:`~LeggedDriverCore.on_frame` frame by frame.

The velocity the robot is sent, every tick: the joystick holder's Joy (set_listen) if someone
holds control; else a fresh velocity command (``set_velocity``, the node's cmd_vel); else the
waypoint follower's; else zero. Services answer "service timeout" (the seed's string for "no
service response") while the lower computer is silent for ``link_timeout``; set_map answers it
too when the emulated robot's mapping plugin (Fast-LIO on the real one) is not loaded.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from lowerbase.clock import Clock
from lowerbase.errors import LowerbaseError, MapError, ProtocolError
from lowerbase.legged_driver import pcdmap, reply_kernel
from lowerbase.legged_driver.joystick import JoyHandover, JoyListenType, JoyMapping
from lowerbase.legged_driver.waypoints import (
    GPS,
    ODOM,
    TIMEOUT,
    FollowerConfig,
    GpsDatum,
    Pose,
    Waypoint,
    WaypointFollower,
)
from lowerbase.protocol.legged import (
    BODY_BUS,
    JOINT_NAMES,
    N_BUSES,
    REPLY_ID,
    REPLY_PREFIX,
    ActuatorLayouts,
    LocomotionState,
    actuator_layouts,
    joint_index,
    legged_codec,
)
from lowerbase.text import point

__all__ = ["JoyListenType", "LeggedDriverConfig", "LeggedDriverCore", "LocomotionState"]

log = logging.getLogger(__name__)

MAP_SAVED = "Map saved."
#: a refusal: this, then the reason (the seed gives only the success string)
MAP_NOT_SAVED = "Map not saved: "
#: an initial_pose quaternion shorter than this is no rotation (others are normalised)
MIN_QUATERNION_NORM = 1e-3
#: BodyVelocityCommand's ranges (legged.dbc)
VX_MAX, VY_MAX, WZ_MAX = 3.0, 3.0, 6.0

Send = Callable[[int, int, bytes], None]


@dataclass
class LeggedDriverConfig:
    command_rate: float = 50.0        # Hz: BodyVelocityCommand and the follower
    link_timeout: float = 0.5         # s without a body frame: the lower computer is silent
    cmd_timeout: float = 0.5          # s: a velocity command older than this is dropped
    gps_datum: GpsDatum | None = None
    mapping_plugin: bool = True       # False: set_map answers "service timeout"
    map_dir: Path | None = None       # where set_map saves NAME.pcd (None: not saved to disk)
    listen_velocity: bool = True      # the node listens to cmd_vel (joy_listen_type VEL_CMD)
    joy_timeout: float = 0.5
    joy: JoyMapping = field(default_factory=JoyMapping)
    follower: FollowerConfig = field(default_factory=FollowerConfig)


@dataclass
class Actuator:
    name: str
    position: float = 0.0
    velocity: float = 0.0
    effort: float = 0.0
    status: int = 0
    temperature: float = 0.0


@dataclass
class LaserMap:
    name: str
    points: np.ndarray
    #: map -> odom: a point p_odom is R(yaw) p_odom + t in the map
    yaw: float
    translation: tuple[float, float, float]
    path: Path | None


def yaw_of(q: Sequence[float]) -> float:
    """Yaw of the quaternion [x, y, z, w]."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class LeggedDriverCore:
    """See the module docstring."""

    def __init__(self, send: Send, clock: Clock, config: LeggedDriverConfig | None = None
                 ) -> None:
        self.send = send
        self.clock = clock
        self.config = config or LeggedDriverConfig()
        self.codec = legged_codec()
        self._decode = self.codec.decode
        self.stats: Counter[str] = Counter()
        #: the actuators' last replies, a row per joint: position [rad], velocity [rad/s],
        #: effort [Nm], temperature [degC], status (the error code)
        self.joints = np.zeros((len(JOINT_NAMES), 5))
        self._tables: ActuatorLayouts | None = None  # on_frames' layouts, made at its first
        self.base_pos = [0.0, 0.0, 0.0]
        self.base_quat = [0.0, 0.0, 0.0, 1.0]
        self.base_lin_vel = [0.0, 0.0, 0.0]
        self.base_ang_vel = [0.0, 0.0, 0.0]
        self.voltage = self.current = self.max_voltage = self.min_voltage = 0.0
        self.body_temperature = 0.0
        self.state = LocomotionState.COMM_DISABLED
        self.fault = 0
        self._last_body = -math.inf
        self._link_shown = False  #: robot_state showed the link up last time (one warning)
        self._velocity = (0.0, 0.0, 0.0)
        self._velocity_at = -math.inf
        self._counter = 0
        self._request_counter = 0
        self.last_command = (0.0, 0.0, 0.0)
        self.laser_map: LaserMap | None = None
        cfg = self.config
        self.joystick = JoyHandover(cfg.joy, joy_timeout=cfg.joy_timeout,
                                    default_type=JoyListenType.VEL_CMD if cfg.listen_velocity
                                    else JoyListenType.NONE)
        self.follower = WaypointFollower(self.resolve, cfg.follower)
        self.listeners: list[Callable[[str], None]] = []

    # -- frames from the lower computer -------------------------------------------------------

    def on_frame(self, bus: int, frame_id: int, data: bytes) -> None:
        """One frame from leg bus ``bus`` (0..3); never raises on bad input."""
        try:
            name, s = self._decode(frame_id, data)
        except LowerbaseError:
            self.stats["malformed"] += 1
            return
        if name == "MotorReply":
            if not 0 <= bus < N_BUSES:
                self.stats["wrong_bus"] += 1
                return
            motor = int(s["MotorId"])
            prefix = REPLY_PREFIX[motor]
            self.joints[joint_index(bus, motor)] = (
                float(s[prefix + "Position"]), float(s[prefix + "Velocity"]),
                float(s[prefix + "Torque"]), float(s["Temperature"]), int(s["Error"]))
            self.stats["motor_reply"] += 1
            return
        if bus != BODY_BUS:
            self.stats["wrong_bus"] += 1
            return
        handler = self._BODY.get(name)
        if handler is None:  # frames the upper computer sends itself (echo): ignored
            self.stats["ignored"] += 1
            return
        self._last_body = self.clock.now()
        handler(self, s)
        self.stats[name] += 1
        for listener in self.listeners:
            listener(name)

    def on_frames(self, buses: np.ndarray, frame_ids: np.ndarray, data: np.ndarray) -> None:
        """Frames ``data`` (n, 8) from leg buses ``buses`` in row order, as :meth:`on_frame`
        takes them one by one: ``buses`` and ``frame_ids`` int64 of length n, ``data`` uint8
        (n, 8) (8-byte payloads only); other arrays are a :class:`~lowerbase.errors.
        ProtocolError`."""
        n = len(frame_ids)
        if not (data.shape == (n, 8) and buses.shape == frame_ids.shape == (n,)
                and data.dtype == np.uint8 and buses.dtype == frame_ids.dtype == np.int64):
            raise ProtocolError(f"on_frames takes int64 buses and frame IDs of one length and "
                                f"a uint8 (n, 8) payload array, not {buses.dtype}"
                                f"{buses.shape}, {frame_ids.dtype}{frame_ids.shape}, "
                                f"{data.dtype}{data.shape}")
        t = self._tables if self._tables is not None else self._batch_tables()
        counts = self._counts
        counts.fill(0)
        r = 0
        while r < n:
            r = reply_kernel.frames(r, buses, frame_ids, data, REPLY_ID, N_BUSES, BODY_BUS,
                                    t.mux_sig, t.mux_scale, t.reply_sig, t.reply_scale,
                                    t.command_sig, t.command_scale, t.big_endian, self.joints,
                                    counts)
            if r < n:
                self.on_frame(int(buses[r]), int(frame_ids[r]), data[r].tobytes())
                r += 1
        stats = self.stats
        for key, count in zip(reply_kernel.COUNT_KEYS, counts.tolist(), strict=True):
            if count:
                stats[key] += count

    def _batch_tables(self) -> ActuatorLayouts:
        self._tables = actuator_layouts(self.codec)
        self._counts = np.zeros(len(reply_kernel.COUNT_KEYS), np.int64)
        return self._tables

    @property
    def actuators(self) -> list[Actuator]:
        """The actuators' last replies by name (robot_state.actuator_states)."""
        return [Actuator(name, p, v, e, int(st), t) for name, (p, v, e, t, st)
                in zip(JOINT_NAMES, self.joints.tolist(), strict=True)]

    def _locomotion(self, s: dict[str, float | int | str]) -> None:
        self.state = LocomotionState(int(s["State"]))
        self.fault = int(s["Fault"])

    def _position(self, s: dict[str, float | int | str]) -> None:
        self.base_pos = [float(s["X"]), float(s["Y"]), float(s["Z"])]

    def _orientation(self, s: dict[str, float | int | str]) -> None:
        q = [float(s[k]) for k in ("QX", "QY", "QZ", "QW")]
        norm = math.sqrt(sum(v * v for v in q))
        self.base_quat = [v / norm for v in q] if norm > 0.5 else self.base_quat

    def _linear(self, s: dict[str, float | int | str]) -> None:
        self.base_lin_vel = [float(s["Vx"]), float(s["Vy"]), float(s["Vz"])]

    def _angular(self, s: dict[str, float | int | str]) -> None:
        self.base_ang_vel = [float(s["Wx"]), float(s["Wy"]), float(s["Wz"])]

    def _temperature(self, s: dict[str, float | int | str]) -> None:
        self.body_temperature = float(s["Body"])

    def _pack(self, s: dict[str, float | int | str]) -> None:
        self.voltage, self.current = float(s["Voltage"]), float(s["Current"])

    def _cell(self, s: dict[str, float | int | str]) -> None:
        self.max_voltage = float(s["CellVoltageMax"])
        self.min_voltage = float(s["CellVoltageMin"])

    def _nothing(self, s: dict[str, float | int | str]) -> None:
        pass

    _BODY: ClassVar[dict[str, Callable[[LeggedDriverCore, dict[str, float | int | str]],
                                       None]]] = {
        "LocomotionStatus": _locomotion, "BasePosition": _position,
        "BaseOrientation": _orientation, "BaseVelocity": _linear,
        "BaseAngularVelocity": _angular, "BodyTemperature": _temperature, "BmsPack": _pack,
        "BmsCell": _cell, "Heartbeat": _nothing, "BmsCapacity": _nothing,
        "BmsStatus": _nothing, "BmsLife": _nothing,
    }

    @property
    def link_up(self) -> bool:
        return self.clock.now() - self._last_body <= self.config.link_timeout

    @property
    def pose(self) -> Pose:
        """The base pose in odom (the lower computer's base pose)."""
        x, y, z = self.base_pos
        return Pose(x, y, z, yaw_of(self.base_quat))

    def robot_state(self) -> dict[str, object]:
        """robot_state's fields (shared/seeds/003). While the lower computer is silent (past
        ``link_timeout``) the state is COMM_DISABLED and the velocities zero: nothing is known
        of them (the last pose and readings stay, as they were last heard)."""
        up = self.link_up
        if not up and self._link_shown:
            log.warning("the lower computer is silent (no body frame for %.1f s): robot_state "
                        "says COMM_DISABLED", self.config.link_timeout)
        self._link_shown = up
        zero = [0.0, 0.0, 0.0]
        return {
            "actuator_states": [vars(a).copy() for a in self.actuators],
            "base_pos": list(self.base_pos), "base_quat": list(self.base_quat),
            "base_lin_vel": list(self.base_lin_vel) if up else zero,
            "base_ang_vel": list(self.base_ang_vel) if up else zero,
            "voltage": self.voltage, "current": self.current,
            "max_voltage": self.max_voltage, "min_voltage": self.min_voltage,
            "body_temperature": self.body_temperature,
            "state": int(self.state) if up else int(LocomotionState.COMM_DISABLED),
            "joy_listen_type": int(self.joystick.listen_type),
        }

    # -- commands to the lower computer -------------------------------------------------------

    def set_velocity(self, vx: float, vy: float, wz: float) -> bool:
        """A velocity command (cmd_vel); refused (counted) while a joystick client holds
        control or when not finite."""
        if self.joystick.holder is not None:
            self.stats["velocity_ignored_joy"] += 1
            return False
        if not all(math.isfinite(v) for v in (vx, vy, wz)):
            self.stats["velocity_rejected"] += 1
            return False
        self._velocity = (vx, vy, wz)
        self._velocity_at = self.clock.now()
        return True

    def on_joy(self, topic: str, axes: Sequence[float]) -> bool:
        return self.joystick.on_joy(topic, axes, self.clock.now())

    def request_state(self, state: LocomotionState) -> None:
        """A LocomotionRequest (stand, walk, sit, ...): the body controller decides."""
        self._request_counter = (self._request_counter + 1) % 16
        self.send(BODY_BUS, self.codec.message("LocomotionRequest").frame_id, self.codec.encode(
            "LocomotionRequest", {"Request": int(state), "Counter": self._request_counter}))

    def command(self) -> tuple[float, float, float]:
        now = self.clock.now()
        joy = self.joystick.command(now)
        if joy is not None:
            return joy
        if now - self._velocity_at <= self.config.cmd_timeout:
            return self._velocity
        if self.follower.active and self.link_up:
            return self.follower.step(self.pose)
        return 0.0, 0.0, 0.0

    def tick(self) -> None:
        """Once per 1/command_rate: send the BodyVelocityCommand."""
        vx, vy, wz = self.command()
        vx = max(-VX_MAX, min(VX_MAX, vx))
        vy = max(-VY_MAX, min(VY_MAX, vy))
        wz = max(-WZ_MAX, min(WZ_MAX, wz))
        self.last_command = (vx, vy, wz)
        self._counter = (self._counter + 1) % 16
        data = self.codec.encode("BodyVelocityCommand",
                                 {"Vx": vx, "Vy": vy, "YawRate": wz, "Counter": self._counter})
        self.send(BODY_BUS, self.codec.message("BodyVelocityCommand").frame_id, data)

    # -- waypoints ----------------------------------------------------------------------------

    def resolve(self, wp: Waypoint) -> tuple[float, float, float]:
        """A waypoint in odom; ValueError naming the problem."""
        if wp.frame == ODOM:
            return wp.x, wp.y, wp.z
        if wp.frame == GPS:
            if self.config.gps_datum is None:
                raise ValueError("gps waypoints need a gps datum: set the node's ~gps_origin "
                                 "[latitude, longitude, altitude, heading]")
            return self.config.gps_datum.to_odom(wp.x, wp.y, wp.z)
        m = self.laser_map
        if m is not None and wp.frame == m.name:
            c, s = math.cos(m.yaw), math.sin(m.yaw)  # invert map <- odom
            dx, dy = wp.x - m.translation[0], wp.y - m.translation[1]
            return c * dx + s * dy, -s * dx + c * dy, wp.z - m.translation[2]
        names = "'odom', 'gps'" + (f" or the map {m.name!r}" if m else " (no map is loaded)")
        raise ValueError(f"unknown frame {wp.frame!r}: use {names}")

    def set_waypoints(self, waypoints: Sequence[Waypoint], repetition: int,
                      current_index: int) -> tuple[bool, str]:
        if not waypoints:
            return False, self.follower.set([], repetition, current_index)[1]
        if not self.link_up:
            return False, TIMEOUT
        return self.follower.set(waypoints, repetition, current_index)

    def stop_waypoints(self) -> tuple[bool, str]:
        """End the waypoint mission now, an endless one too (the node's ~stop_waypoints: the
        seed has no such call and refuses an empty list); answered also while the lower
        computer is silent, as stopping must always work."""
        return self.follower.stop()

    def get_waypoints(self) -> tuple[bool, str, list[Waypoint], int, int]:
        if not self.link_up:
            return False, TIMEOUT, [], 0, 0
        return self.follower.get()

    def append_waypoint(self, waypoint: Waypoint) -> tuple[bool, str]:
        if not self.link_up:
            return False, TIMEOUT
        return self.follower.append(waypoint)

    # -- set_map / set_listen -----------------------------------------------------------------

    def set_map(self, name: str, cloud: object, initial_pose: Sequence[float]) -> tuple[bool, str]:
        """Load a point-cloud map and initialise localization: the robot is at
        ``initial_pose`` (x, y, z, qx, qy, qz, qw) in the map now."""
        if not self.config.mapping_plugin or not self.link_up:
            return False, TIMEOUT
        try:
            pcdmap.check_name(name)
            if len(initial_pose) != 7 or not all(math.isfinite(v) for v in initial_pose):
                raise MapError(f"initial_pose must be 7 finite numbers, got "
                               f"{point(*initial_pose)}")
            q = initial_pose[3:]
            norm = math.sqrt(sum(v * v for v in q))
            if norm < MIN_QUATERNION_NORM:
                raise MapError(f"initial_pose orientation {point(*q, decimals=0)} is not a "
                               f"rotation (norm {norm:.3g}): send a unit quaternion, e.g. "
                               f"(0, 0, 0, 1)")
            points = pcdmap.cloud_points(cloud)
            path = None
            if self.config.map_dir is not None:
                path = pcdmap.write_pcd(self.config.map_dir / f"{name}.pcd", points)
        except MapError as exc:
            self.stats["set_map_refused"] += 1
            log.warning("set_map refused: %s", exc)
            return False, f"{MAP_NOT_SAVED}{exc}"
        pose = self.pose
        map_yaw = yaw_of([v / norm for v in q])  # normalised, as tf does
        yaw = map_yaw - pose.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        t = (initial_pose[0] - (c * pose.x - s * pose.y),
             initial_pose[1] - (s * pose.x + c * pose.y), initial_pose[2] - pose.z)
        self.laser_map = LaserMap(name, points, yaw, t, path)
        log.info("map %r: %d points, map->odom yaw %.3f rad, t %s", name, len(points), yaw, t)
        return True, MAP_SAVED

    def pose_in_map(self) -> Pose | None:
        """Localization's estimate of the base pose in the loaded map, or None."""
        m, p = self.laser_map, self.pose
        if m is None:
            return None
        c, s = math.cos(m.yaw), math.sin(m.yaw)
        return Pose(c * p.x - s * p.y + m.translation[0], s * p.x + c * p.y + m.translation[1],
                    p.z + m.translation[2], math.remainder(p.yaw + m.yaw, math.tau))

    def set_listen(self, data: str) -> tuple[bool, str]:
        ok, message = self.joystick.request(data)
        if ok and self.joystick.holder is not None:
            self._velocity_at = -math.inf  # a joystick takes over from a velocity command
        return ok, message
