"""The legged robot's waypoint mission (planning/set_waypoints, get_waypoints, append_waypoint).

ROS-free. A :class:`WaypointFollower` holds the list, the remaining laps and the current index
and, once per control period, turns the robot's pose into a body velocity command (vx, vy, wz)
towards the current waypoint; the caller sends that command to the lower computer.

Frames of a waypoint (shared/seeds/003, ``Waypoint.frame``):

* ``"odom"``: x, y, z in the odometry frame of the lower computer's base pose;
* ``"gps"``: x = latitude, y = longitude (degrees, WGS84), z = altitude (m, ellipsoidal); made
  local with pymap3d's geodetic -> ENU (exact on the ellipsoid, no flat-earth guess) about a
  configured :class:`GpsDatum`, the geodetic position of the odom origin and the heading of
  odom's x axis;
* the name of the loaded point-cloud map (set_map's ``name``; the seed calls this frame
  "map_name"): map coordinates, brought into odom with localization's map -> odom transform.

Bounds: every coordinate within :data:`MAX_RANGE` (10 km; gps: latitude within -90..90 deg,
longitude within -180..180 deg) and the point it resolves to in odom within 10 km of the odom
origin; anything else is refused (a waypoint at 1e308 would be walked toward for ever).

Repetition: ``repetition`` laps of the list, 0 = endless; the first lap starts at
``current_index``, every further lap at 0. get_waypoints reports the laps still to be walked
including the current one (0 while endless, and 0 once the mission is complete). The seed has
no call that ends a mission (an empty list is refused): :meth:`WaypointFollower.stop` does
(the node's ``~stop_waypoints``).
``use_z``: the waypoint counts as reached only when the base height is within ``z_tolerance``
too (the robot cannot command its height: it keeps closing in on the spot, which brings a
ramp's height with it, and otherwise waits there, reported in ``status``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from lowerbase.text import num, point

ODOM = "odom"
GPS = "gps"
#: the seed's response messages
SET_SUCCESS = "set waypoint success"
EMPTY = "waypoint list is empty"
TIMEOUT = "service timeout"
STOPPED = "waypoint mission stopped"
#: [m] a waypoint's coordinates, and where it resolves to in odom, lie within +- this
MAX_RANGE = 10_000.0
#: current_index and repetition are uint8 on the wire
MAX_WAYPOINTS = 256


@dataclass(frozen=True)
class Waypoint:
    frame: str
    x: float
    y: float
    z: float = 0.0
    use_z: bool = False


@dataclass(frozen=True)
class GpsDatum:
    """Where the odom origin is on the earth: WGS84 latitude/longitude [deg], ellipsoidal
    altitude [m], and the heading of odom's x axis [rad, counterclockwise from east]."""

    latitude: float
    longitude: float
    altitude: float = 0.0
    heading: float = 0.0

    def __post_init__(self) -> None:
        values = (self.latitude, self.longitude, self.altitude, self.heading)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"gps datum must be finite, got {values}")
        if not -90.0 <= self.latitude <= 90.0 or not -180.0 <= self.longitude <= 180.0:
            raise ValueError(f"gps datum latitude/longitude out of range: {values[:2]}")

    def to_odom(self, latitude: float, longitude: float, altitude: float) -> tuple[
            float, float, float]:
        """(x, y, z) in odom of a geodetic point: ENU about the datum, rotated by heading;
        ValueError for a latitude/longitude off the earth."""
        import pymap3d

        check_geodetic(latitude, longitude)

        east, north, up = pymap3d.geodetic2enu(latitude, longitude, altitude, self.latitude,
                                               self.longitude, self.altitude)
        c, s = math.cos(self.heading), math.sin(self.heading)
        return (float(c * east + s * north), float(-s * east + c * north), float(up))


def check_geodetic(latitude: float, longitude: float) -> None:
    """ValueError unless latitude is within -90..90 deg and longitude within -180..180 deg."""
    if not -90.0 <= latitude <= 90.0:
        raise ValueError(f"gps latitude {latitude:.10g} is outside -90..90 deg")
    if not -180.0 <= longitude <= 180.0:
        raise ValueError(f"gps longitude {longitude:.10g} is outside -180..180 deg")


def _in_range(values: tuple[float, float, float], what: str) -> None:
    if not all(abs(v) <= MAX_RANGE for v in values):
        raise ValueError(f"{what} {point(*values)} must lie within +-{MAX_RANGE:g} m")


@dataclass(frozen=True)
class Pose:
    """A planar pose with height: x, y, z [m] and yaw [rad]."""

    x: float
    y: float
    z: float
    yaw: float


@dataclass(frozen=True)
class FollowerConfig:
    xy_tolerance: float = 0.15      # m: a waypoint is reached within this distance
    z_tolerance: float = 0.10       # m: and, with use_z, within this height
    max_linear: float = 0.6         # m/s forward
    max_lateral: float = 0.3        # m/s sideways
    max_angular: float = 1.0        # rad/s
    linear_gain: float = 1.0        # 1/s: speed = gain x distance, clipped
    angular_gain: float = 1.5       # 1/s: yaw rate = gain x bearing, clipped


#: resolves a waypoint into odom (x, y, z), or raises ValueError saying why it cannot
Resolver = Callable[[Waypoint], tuple[float, float, float]]


class WaypointFollower:
    """The mission state and its controller (see the module docstring)."""

    def __init__(self, resolve: Resolver, config: FollowerConfig | None = None) -> None:
        self.resolve = resolve
        self.config = config or FollowerConfig()
        self.waypoints: list[Waypoint] = []
        self.repetition = 0       # as set: 0 = endless
        self.laps_left = 0        # laps still to walk, including the current one
        self.current_index = 0
        self.active = False
        self.laps_done = 0
        self.reached = 0          # waypoints reached since the mission was set
        self.status = "idle"

    # -- services ----------------------------------------------------------------------------

    def _check(self, waypoints: Sequence[Waypoint]) -> str | None:
        for i, wp in enumerate(waypoints):
            xyz = (wp.x, wp.y, wp.z)
            if not all(math.isfinite(v) for v in xyz):
                return f"waypoint {i}: coordinates must be finite, got {point(*xyz)}"
            try:
                if wp.frame == GPS:
                    check_geodetic(wp.x, wp.y)
                    if abs(wp.z) > MAX_RANGE:
                        raise ValueError(f"gps altitude {num(wp.z)} m must lie within "
                                         f"+-{MAX_RANGE:g} m")
                else:
                    _in_range(xyz, "x, y, z")
                _in_range(self.resolve(wp), "the point in odom")
            except ValueError as exc:
                return f"waypoint {i}: {exc}"
        return None

    def set(self, waypoints: Sequence[Waypoint], repetition: int, current_index: int) -> tuple[
            bool, str]:
        """planning/set_waypoints: replace the mission (refused as a whole, nothing changes)."""
        if not waypoints:
            return False, EMPTY
        if len(waypoints) > MAX_WAYPOINTS:
            return False, f"at most {MAX_WAYPOINTS} waypoints (current_index is a uint8)"
        if not 0 <= current_index < len(waypoints):
            return False, (f"current_index {current_index} is out of range for "
                           f"{len(waypoints)} waypoints")
        if not 0 <= repetition <= 255:
            return False, f"repetition {repetition} is not a uint8"
        problem = self._check(waypoints)
        if problem:
            return False, problem
        self.waypoints = list(waypoints)
        self.repetition = repetition
        self.laps_left = repetition
        self.current_index = current_index
        self.active = True
        self.laps_done = 0
        self.reached = 0
        self.status = f"to waypoint {current_index}"
        return True, SET_SUCCESS

    def append(self, waypoint: Waypoint) -> tuple[bool, str]:
        """planning/append_waypoint. Appending to a finished or empty mission walks on from
        the new waypoint, one pass."""
        if len(self.waypoints) >= MAX_WAYPOINTS:
            return False, f"at most {MAX_WAYPOINTS} waypoints (current_index is a uint8)"
        problem = self._check([waypoint])
        if problem:
            return False, problem.replace("waypoint 0", f"waypoint {len(self.waypoints)}")
        self.waypoints.append(waypoint)
        if not self.active:
            self.current_index = len(self.waypoints) - 1
            self.repetition = self.laps_left = 1
            self.active = True
            self.status = f"to waypoint {self.current_index}"
        return True, f"waypoint appended at index {len(self.waypoints) - 1}"

    def get(self) -> tuple[bool, str, list[Waypoint], int, int]:
        """planning/get_waypoints: (success, message, waypoints, laps left, current index)."""
        if not self.waypoints:
            return True, EMPTY, [], 0, 0
        if not self.active:
            message = STOPPED if self.status == STOPPED else "mission complete"
        else:
            lap = "endless" if self.repetition == 0 else f"{self.laps_left} lap(s) left"
            message = f"{self.status} of {len(self.waypoints)}, {lap}"
        return True, message, list(self.waypoints), self.laps_left, self.current_index

    def stop(self) -> tuple[bool, str]:
        """End the mission now (also an endless one); the list stays for get_waypoints, with 0
        laps left. Appending walks on from the new waypoint, as after a finished mission."""
        if not self.active:
            return True, "no waypoint mission is running"
        self.active = False
        self.laps_left = 0
        self.status = STOPPED
        return True, STOPPED

    # -- control -----------------------------------------------------------------------------

    def target(self) -> tuple[float, float, float] | None:
        """The current waypoint in odom, or None when idle or unresolvable right now."""
        if not self.active:
            return None
        try:
            return self.resolve(self.waypoints[self.current_index])
        except ValueError as exc:
            self.status = f"waypoint {self.current_index} unresolvable: {exc}"
            return None

    def _advance(self) -> None:
        self.reached += 1
        self.current_index += 1
        if self.current_index < len(self.waypoints):
            self.status = f"to waypoint {self.current_index}"
            return
        self.laps_done += 1
        if self.repetition != 0:
            self.laps_left -= 1
            if self.laps_left <= 0:
                self.laps_left = 0
                self.current_index = len(self.waypoints) - 1
                self.active = False
                self.status = "mission complete"
                return
        self.current_index = 0
        self.status = "to waypoint 0"

    def step(self, pose: Pose) -> tuple[float, float, float]:
        """Body velocity (vx, vy, wz) for this period; reaching a waypoint advances the list
        (within the same call, so the command already heads for the next one)."""
        cfg = self.config
        for _ in range(len(self.waypoints) + 1):  # several waypoints may be reached at once
            goal = self.target()
            if goal is None:
                return 0.0, 0.0, 0.0
            dx, dy = goal[0] - pose.x, goal[1] - pose.y
            distance = math.hypot(dx, dy)
            if distance > cfg.xy_tolerance:
                break
            wp = self.waypoints[self.current_index]
            if wp.use_z and abs(goal[2] - pose.z) > cfg.z_tolerance:
                # keep closing in on the spot (the height may come with it: a ramp, a step)
                self.status = (f"at waypoint {self.current_index}, height {pose.z:.2f} m "
                               f"!= {goal[2]:.2f} m")
                break
            self._advance()
        else:  # every waypoint within tolerance of the robot, endless: stand still
            return 0.0, 0.0, 0.0
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        bx, by = c * dx + s * dy, -s * dx + c * dy  # the goal in the body frame
        if distance < 1e-9:
            return 0.0, 0.0, 0.0
        speed = min(cfg.linear_gain * distance, 1.0)  # fraction of the limits
        vx = max(-cfg.max_linear, min(cfg.max_linear, speed * cfg.max_linear * bx / distance))
        vy = max(-cfg.max_lateral, min(cfg.max_lateral, speed * cfg.max_lateral * by / distance))
        bearing = math.atan2(by, bx)
        wz = max(-cfg.max_angular, min(cfg.max_angular, cfg.angular_gain * bearing))
        return vx, vy, wz

    def snapshot(self) -> dict[str, object]:
        return {"active": self.active, "current_index": self.current_index,
                "laps_left": self.laps_left, "laps_done": self.laps_done,
                "reached": self.reached, "status": self.status,
                "waypoints": [replace(w) for w in self.waypoints]}
