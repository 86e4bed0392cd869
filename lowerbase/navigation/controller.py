"""The local controller: follows a global plan with a regulated pure-pursuit law, ROS-free.

One :meth:`PathController.compute` per control period (move_base's ``controller_frequency``,
20 Hz by default) takes the robot's pose (the localization estimate in the map frame, or /odom
when map = odom) and answers a twist for /base_cmd_vel and a status:

- **rotate in place** towards the path first when the heading is off by more than
  ``rotate_threshold`` (as regulated pure pursuit's rotate-to-heading);
- **pure pursuit** along the path: the carrot ``lookahead`` metres ahead (scaled with speed),
  curvature ``2 y / L^2``; the speed is regulated down on tight curvature, on cost under the
  robot (near obstacles) and to brake onto the goal (``sqrt(2 a d)``);
- **final approach**, closed loop on the pose: within ``approach_distance`` of the goal the
  robot drives straight at the goal point (backwards if it lies behind), then rotates in place
  to the goal's yaw to within half the tolerances, then stops; SUCCEEDED once the robot
  stands still (:data:`SETTLE_PERIODS` poses within :data:`STILL_DISTANCE` /
  :data:`STILL_ANGLE`, as base_local_planner's goal check wants the robot in tolerance *and*
  stopped) within ``xy_tolerance`` and ``yaw_tolerance`` (defaults 5 cm, 2 deg). A robot
  that coasted past them (its pose or the command late on a busy host) turns back instead of
  being reported at a goal it is not at;
- **collision check**: the footprint is projected along the commanded arc over the braking
  distance plus a margin; if it meets a LETHAL cell the command brakes to zero and the status
  is BLOCKED (the caller replans or waits).

Every command respects maxLinear/maxAngular and the acceleration/deceleration limits of the
chassis parameters read by driver_base (:meth:`Limits.from_parameters`, woosh names).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from lowerbase.errors import ConfigError
from lowerbase.navigation.planner import LETHAL, NO_INFORMATION, FootprintCells, Pose
from lowerbase.navigation.pursuit_kernels import arc_hits_lethal, first_beyond, nearest_ahead

#: the final stop: the pose stands still this many periods in a row before it is judged
SETTLE_PERIODS = 3
STILL_DISTANCE = 0.0003  #: [m] "still": within this of the pose the count started from
STILL_ANGLE = math.radians(0.02)  #: [rad]
#: [periods] a stop is judged after this at the latest (a pose that never settles)
SETTLE_TIMEOUT = 40


def wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class Limits:
    """Velocity and acceleration limits [m/s, rad/s, m/s^2, rad/s^2]."""

    max_linear: float = 1.2
    max_angular: float = 1.0
    linear_accel: float = 0.8
    linear_decel: float = 1.0
    angular_accel: float = 1.5
    angular_decel: float = 2.0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"limit {name} must be a number > 0, got {value}")

    @classmethod
    def from_parameters(cls, params: Mapping[str, float]) -> Limits:
        """From the chassis parameters as driver_base reads them (woosh names: maxLinear,
        maxAngular, linearAccelLimit, linearDecelLimit, angularAccelLimit, angularDecelLimit);
        a missing one keeps the default."""
        d = cls()
        return cls(params.get("maxLinear", d.max_linear), params.get("maxAngular", d.max_angular),
                   params.get("linearAccelLimit", d.linear_accel),
                   params.get("linearDecelLimit", d.linear_decel),
                   params.get("angularAccelLimit", d.angular_accel),
                   params.get("angularDecelLimit", d.angular_decel))


@dataclass(frozen=True)
class ControllerConfig:
    max_speed: float = 0.6  #: cruise speed [m/s] (<= maxLinear)
    max_rotation: float = 0.8  #: rotate-in-place speed [rad/s] (<= maxAngular)
    xy_tolerance: float = 0.05  #: [m]
    yaw_tolerance: float = math.radians(2.0)  #: [rad]
    lookahead: float = 0.6  #: carrot distance at cruise speed [m]
    min_lookahead: float = 0.3  #: [m]
    rotate_threshold: float = math.radians(45.0)  #: rotate in place above this heading error
    min_turn_radius: float = 0.9  #: below this radius the speed is scaled down [m]
    approach_distance: float = 0.3  #: final approach within this of the goal [m]
    min_speed: float = 0.02  #: slowest useful linear speed [m/s] (above the wheels' minSpeed)
    min_rotation: float = 0.06  #: slowest useful rotation [rad/s]
    cost_slowdown: float = 0.6  #: speed fraction removed at cost 252 under the robot
    check_margin: float = 0.15  #: collision check beyond the braking distance [m]
    period: float = 0.05  #: control period [s] (20 Hz)

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"controller {name} must be a number > 0, got {value}")


class Status(enum.Enum):
    IDLE = "idle"  #: no plan
    ROTATING = "rotating"  #: rotating in place onto the path
    FOLLOWING = "following"
    APPROACHING = "approaching"  #: final approach: position, then yaw
    SUCCEEDED = "succeeded"
    BLOCKED = "blocked"  #: lethal cost ahead: braking to a stop
    WAITING = "waiting"  #: stopped: the scan or the localization is out of date (Navigator)


@dataclass(frozen=True)
class Command:
    linear: float
    angular: float
    status: Status
    reason: str = ""


class PathController:
    """Regulated pure pursuit on one cost array (see the module docstring)."""

    def __init__(self, costs: np.ndarray, resolution: float, origin: Sequence[float] = (0, 0),
                 *, footprint: Sequence[tuple[float, float]], limits: Limits | None = None,
                 config: ControllerConfig | None = None) -> None:
        self.limits = limits or Limits()
        self.config = config or ControllerConfig()
        self.footprint = FootprintCells(footprint, resolution)
        self.set_costmap(costs, resolution, origin)
        self.path = np.empty((0, 3))
        self.v = self.w = 0.0
        self._index = 0
        self._phase = Status.IDLE
        self._at_position = False
        #: the final stop: (the pose the still count started from, its count, periods stopped)
        self._settle: tuple[Pose, int, int] | None = None
        #: final stops that stood outside the tolerances and turned back (a late pose/command)
        self.overshoots = 0

    def set_costmap(self, costs: np.ndarray, resolution: float, origin: Sequence[float]) -> None:
        if resolution != self.footprint.resolution:
            self.footprint = FootprintCells(
                [(float(px), float(py)) for px, py in self.footprint.points], resolution)
        self.costs = np.asarray(costs, dtype=np.uint8)
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))

    def set_plan(self, poses: Sequence[Pose]) -> None:
        """A new plan (map frame); the robot starts by turning onto it if needed."""
        path = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, 3))
        if not np.isfinite(path).all():
            raise ConfigError("a plan must hold finite (x, y, yaw) poses")
        self.path = path
        self._index = 0
        self._phase = Status.ROTATING if len(path) else Status.IDLE
        self._at_position = False
        self._settle = None

    @property
    def goal(self) -> Pose | None:
        if not len(self.path):
            return None
        x, y, yaw = self.path[-1]
        return float(x), float(y), float(yaw)

    # -- the law --------------------------------------------------------------------------------
    def compute(self, pose: Sequence[float]) -> Command:
        """The twist for this control period from the robot's pose (x, y, yaw)."""
        x, y, yaw = (float(v) for v in pose)
        if self._phase in (Status.IDLE, Status.SUCCEEDED) or not len(self.path):
            return self._out(0.0, 0.0, self._phase)
        cfg = self.config
        gx, gy, gyaw = self.path[-1]
        dist_goal = math.hypot(gx - x, gy - y)
        if self._phase is not Status.APPROACHING and dist_goal < cfg.approach_distance:
            self._phase = Status.APPROACHING
        if self._phase is Status.APPROACHING:
            return self._approach(x, y, yaw, gx, gy, gyaw, dist_goal)
        self._advance(x, y)
        before = self.v, self.w
        command = self._pursue(x, y, yaw, dist_goal, tight=False)
        if command.status is Status.BLOCKED and self._phase is Status.FOLLOWING:
            self.v, self.w = before
            # the arc cuts a corner the path itself clears: track the path tightly and slowly
            command = self._pursue(x, y, yaw, dist_goal, tight=True)
        return command

    def _pursue(self, x: float, y: float, yaw: float, dist_goal: float, tight: bool
                ) -> Command:
        cfg = self.config
        tx, ty = self._carrot(x, y, tight)
        dx, dy = tx - x, ty - y
        ex = math.cos(yaw) * dx + math.sin(yaw) * dy
        ey = -math.sin(yaw) * dx + math.cos(yaw) * dy
        alpha = math.atan2(ey, ex)
        if self._phase is Status.ROTATING:
            if abs(alpha) <= cfg.rotate_threshold / 3.0:
                self._phase = Status.FOLLOWING
            else:
                return self._rotate(x, y, yaw, alpha, Status.ROTATING)
        if abs(alpha) > cfg.rotate_threshold:
            self._phase = Status.ROTATING
            return self._rotate(x, y, yaw, alpha, Status.ROTATING)
        ld2 = max(ex * ex + ey * ey, 1e-9)
        curvature = 2.0 * ey / ld2
        v = cfg.max_speed * (0.3 if tight else 1.0)
        if abs(curvature) > 1.0 / cfg.min_turn_radius:
            v *= 1.0 / (cfg.min_turn_radius * abs(curvature))
        cost = self._cost_at(x, y)
        v *= 1.0 - cfg.cost_slowdown * min(cost, 252) / 252.0
        v = min(v, math.sqrt(2.0 * self.limits.linear_decel * 0.8 * dist_goal))
        v = max(min(v, self.limits.max_linear), cfg.min_speed)
        w = v * curvature
        if abs(w) > self.limits.max_angular:
            v *= self.limits.max_angular / abs(w)
            w = math.copysign(self.limits.max_angular, w)
        return self._checked(x, y, yaw, v, w, Status.FOLLOWING)

    def _approach(self, x: float, y: float, yaw: float, gx: float, gy: float, gyaw: float,
                  dist: float) -> Command:
        cfg = self.config
        if dist > cfg.xy_tolerance:
            self._at_position = False
            self._settle = None
        if not self._at_position and dist <= 0.5 * cfg.xy_tolerance:
            self._at_position = True
        if not self._at_position:
            dx, dy = gx - x, gy - y
            ex = math.cos(yaw) * dx + math.sin(yaw) * dy
            ey = -math.sin(yaw) * dx + math.cos(yaw) * dy
            sign = 1.0 if ex >= 0 else -1.0
            alpha = math.atan2(sign * ey, sign * ex)  # heading error, backwards if behind
            # turn to face the goal point when far off heading; within xy_tolerance only when
            # driving straight cannot reach the half tolerance (the error mostly sideways):
            # creeping to and fro there never got closer than |ey| (a livelock until "stuck")
            if abs(alpha) > math.radians(20.0) and (
                    dist > cfg.xy_tolerance or abs(ey) > 0.5 * cfg.xy_tolerance):
                return self._rotate(x, y, yaw, alpha, Status.APPROACHING)
            v = sign * min(max(1.2 * abs(ex), cfg.min_speed), cfg.max_speed,
                           math.sqrt(2.0 * self.limits.linear_decel * 0.5 * dist))
            w = min(max(2.0 * alpha, -cfg.max_rotation), cfg.max_rotation) \
                if abs(ex) > 0.5 * cfg.xy_tolerance else 0.0
            # the robot stops at the goal: check up to it, not the margin beyond (a goal at a
            # rack face was BLOCKED creeping, free stopped: every other period)
            return self._checked(x, y, yaw, v, w, Status.APPROACHING, up_to=dist)
        err = wrap(gyaw - yaw)
        if self._settle is None and abs(err) > 0.5 * cfg.yaw_tolerance:
            return self._rotate(x, y, yaw, err, Status.APPROACHING)
        return self._stop_and_judge((x, y, yaw), err, dist)

    def _stop_and_judge(self, pose: Pose, err: float, dist: float) -> Command:
        """Zero, until the pose stands still (or :data:`SETTLE_TIMEOUT`); then SUCCEEDED
        within the tolerances, else the approach goes on from where the robot stands."""
        cfg = self.config
        start, still, periods = self._settle or (pose, -1, 0)
        if abs(wrap(pose[2] - start[2])) <= STILL_ANGLE \
                and math.hypot(pose[0] - start[0], pose[1] - start[1]) <= STILL_DISTANCE:
            still += 1
        else:
            start, still = pose, 0
        self._settle = (start, still, periods + 1)
        if still < SETTLE_PERIODS and periods + 1 < SETTLE_TIMEOUT:
            return self._out(0.0, 0.0, Status.APPROACHING)
        self._settle = None
        if abs(err) <= cfg.yaw_tolerance and dist <= cfg.xy_tolerance:
            self._phase = Status.SUCCEEDED
            return self._out(0.0, 0.0, Status.SUCCEEDED)
        self.overshoots += 1  # coasted past the yaw tolerance (dist is within: see _approach)
        return self._rotate(*pose, err, Status.APPROACHING)

    def _rotate(self, x: float, y: float, yaw: float, err: float, status: Status) -> Command:
        cfg = self.config
        w = min(max(abs(err) * 1.5, cfg.min_rotation), cfg.max_rotation,
                self.limits.max_angular,
                math.sqrt(2.0 * self.limits.angular_decel * 0.5 * abs(err)))
        return self._checked(x, y, yaw, 0.0, math.copysign(w, err), status)

    # -- safety and limits ----------------------------------------------------------------------
    def _checked(self, x: float, y: float, yaw: float, v: float, w: float,
                 status: Status, up_to: float = math.inf) -> Command:
        """The command if the footprint stays off lethal cells along its arc over the braking
        distance (+ margin, at most ``up_to`` m: the goal, as nav2's regulated pure pursuit
        checks up to the carrot); else braking and BLOCKED."""
        v_next, w_next = self._ramp(v, w)
        reach, turn, n = self._arc_extent(v_next, w_next, up_to)
        fp = self.footprint
        if arc_hits_lethal(self.costs, self.origin[0], self.origin[1], self.resolution, x, y,
                           yaw, v_next, w_next, reach, turn, n, fp.bins, fp.dr_table, fp.dc_table,
                           LETHAL, NO_INFORMATION):
            v_stop, w_stop = self._ramp(0.0, 0.0)
            return self._out(v_stop, w_stop, Status.BLOCKED, "an obstacle ahead of the robot")
        if status is not self._phase and self._phase is Status.BLOCKED:
            self._phase = status
        return self._out(v_next, w_next, status)

    def _arc_extent(self, v: float, w: float, up_to: float) -> tuple[float, float, int]:
        """How far the collision check looks for the command (v, w): (reach [m]: the braking
        distance + margin + a period, at most ``up_to``; turn [rad]: the same for the
        rotation; n: the poses checked along it)."""
        lim, cfg = self.limits, self.config
        reach = v * v / (2.0 * lim.linear_decel) + cfg.check_margin + abs(v) * cfg.period
        reach = min(reach, max(up_to, abs(v) * cfg.period))
        turn = w * w / (2.0 * lim.angular_decel) + abs(w) * cfg.period + 0.05
        n = max(3, math.ceil(reach / (0.5 * self.resolution)), math.ceil(turn / 0.02))
        return reach, turn, n

    def _ramp(self, v: float, w: float) -> tuple[float, float]:
        """The command one period closer to (v, w) within the acceleration limits."""
        lim, dt = self.limits, self.config.period
        v = min(max(v, -lim.max_linear), lim.max_linear)
        w = min(max(w, -lim.max_angular), lim.max_angular)
        dv = (lim.linear_accel if abs(v) > abs(self.v) and v * self.v >= 0 else lim.linear_decel)
        dw = (lim.angular_accel if abs(w) > abs(self.w) and w * self.w >= 0
              else lim.angular_decel)
        v = self.v + min(max(v - self.v, -dv * dt), dv * dt)
        w = self.w + min(max(w - self.w, -dw * dt), dw * dt)
        return v, w

    def _out(self, v: float, w: float, status: Status, reason: str = "") -> Command:
        self.v, self.w = v, w
        return Command(v, w, status, reason)

    # -- path bookkeeping -----------------------------------------------------------------------
    def _advance(self, x: float, y: float) -> None:
        """Move the progress index to the nearest path point in a window ahead."""
        end = min(len(self.path), self._index + max(20, int(2.0 / self.resolution)))
        self._index = nearest_ahead(self.path, self._index, end, x, y)

    def _carrot(self, x: float, y: float, tight: bool = False) -> tuple[float, float]:
        cfg = self.config
        ld = min(max(cfg.lookahead * abs(self.v) / cfg.max_speed, cfg.min_lookahead),
                 cfg.lookahead)
        if tight:
            ld = 0.5 * cfg.min_lookahead
        # the first point at least ld away from the progress index (compiled)
        k = first_beyond(self.path, self._index, x, y, ld)
        return float(self.path[k, 0]), float(self.path[k, 1])

    def _cost_at(self, x: float, y: float) -> int:
        r = math.floor((y - self.origin[1]) / self.resolution)
        c = math.floor((x - self.origin[0]) / self.resolution)
        h, w = self.costs.shape
        if not (0 <= r < h and 0 <= c < w):
            return LETHAL
        value = int(self.costs[r, c])
        return 0 if value == NO_INFORMATION else value
