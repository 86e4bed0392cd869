"""What TraceNavigate and ObstacleNavigate share, ROS-free on an injected clock.

A :class:`Navigator` takes the seed's messages in (``on_route``, ``on_scan``, ``on_pose``) and
publishes through two callables (the GTraceList report, the GRobotSpeedControl). ``tick()`` runs
one control period (20 Hz). It keeps a local costmap (lowerbase.navigation: the obstacle layer
marked and cleared from each scan, inflated) and drives with the navigation's
:class:`~lowerbase.navigation.controller.PathController`, whose collision check on that costmap
is what stops the robot in front of an obstacle.

Answers common to both modules: an empty list cancels (zero speed at once, IDLE reported once);
a list that cannot be driven (a point off the map included) is refused
(:func:`~lowerbase.trace.messages.check_route`: logged, counted in ``stats["refused"]``,
answered once with the list as received and IDLE); a list while
one RUNS is refused the same way but answered with the running list, RUNNING. A scan or pose
with NaN where a number is needed is dropped and counted.

A scan is put on the costmaps from the pose of its own time, as tf's message filter does: the
first pose stamped at or after the scan's stamp (poses are kept for
:data:`POSE_HISTORY`). Scans newer than every pose wait (:data:`SCANS_WAITING` of them, as
tf's message filter queues them): a pose takes the newest waiting scan its stamp reaches, the
older ones are counted as ``scan_superseded`` (the costmaps mark the newest view). So when the
poses lag the scans by more than a scan period (a busy host: the localization waits for
/odom), every pose still pairs with a scan; with one waiting slot each new scan replaced the
one the next pose would have taken and the costmaps stopped updating. A scan that arrives
late on a busy host is so marked where the robot was, not smeared along where it has turned
since (issue 22 item 18). A scan older than every kept pose is dropped and counted
(``scan_too_old``); unstamped messages (stamp 0) pair with the latest pose.
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from lowerbase.clock import Clock
from lowerbase.errors import ConfigError, worth_logging
from lowerbase.navigation.controller import (
    Command,
    ControllerConfig,
    Limits,
    PathController,
    Status,
)
from lowerbase.navigation.costmap import CostmapParams, local_costmap
from lowerbase.trace import messages as m
from lowerbase.trace.bridges import laser_from_pb
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, DEFAULT_PADDING, Footprint
from lowerbase.world.lidar import LaserScan

log = logging.getLogger(__name__)
#: poses kept to pair a late scan with the pose of its time (20 Hz: 5 s)
POSE_HISTORY = 100
#: scans kept while newer than every pose (25 Hz: 2 s)
SCANS_WAITING = 50

Pose = tuple[float, float, float]
Publish = Callable[[m.GTraceList], None]
PublishSpeed = Callable[[m.GRobotSpeedControl], None]


@dataclass(frozen=True)
class TraceParams:
    """The module's parameters (seed defaults: a report every 5 s, BLOCKED after 60 s)."""

    status_period: float = 5.0  #: [s] RUNNING reports while a task runs
    blocked_timeout: float = 60.0  #: [s] stopped by an obstacle this long: BLOCKED
    default_speed: float = 0.5  #: [m/s] for points without a speed
    avoid_speed: float = 0.3  #: [m/s] ObstacleNavigate's cruise speed
    period: float = 0.05  #: [s] control period (tick)
    map_name: str = ""  #: the map this module runs on ("" accepts any list's map)
    rejoin_margin: float = 0.8  #: [m] clear route beyond the obstacle to rejoin at
    lookahead: float = 12.0  #: [m] how far along the route ObstacleNavigate looks
    replan_period: float = 2.0  #: [s] ObstacleNavigate replans this often while driving
    max_blocked_detour: float = 10.0  #: [s] a detour blocked this long fails (BLOCKED)
    backoff: float = 0.28  #: [m] ObstacleNavigate backs off this far before its detour

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if name != "map_name" and not (math.isfinite(value) and value > 0):
                raise ConfigError(f"trace parameter {name} must be a number > 0, got {value}")


class Navigator:
    """The shared half of both modules (see the module docstring)."""

    name = "navigator"

    def __init__(self, clock: Clock, publish: Publish, publish_speed: PublishSpeed,
                 params: TraceParams | None = None, *, limits: Limits | None = None,
                 footprint: Footprint = DEFAULT_FOOTPRINT,
                 extent: m.Extent | None = None) -> None:
        self.clock = clock
        #: the map's area [m]: a list with a point outside it is refused (None: not checked)
        self.extent = extent
        self.params = params or TraceParams()
        self._publish = publish
        self._publish_speed = publish_speed
        self.limits = limits or Limits()
        self.footprint = footprint.padded(DEFAULT_PADDING)
        self.local = local_costmap(None, (0.0, 0.0, 0.0), CostmapParams(
            width=6.0, height=6.0, static_map=False, footprint=footprint))
        self.ctl = PathController(self.local.costs, self.local.resolution, self.local.origin,
                                  footprint=self.footprint.points, limits=self.limits,
                                  config=ControllerConfig(period=self.params.period))
        self.pose: Pose | None = None
        self.status: int = m.IDLE
        self.route: m.Route | None = None
        self.finished: list[float] = []
        self.stats: Counter[str] = Counter()
        self.reports: list[tuple[float, m.GTraceList]] = []  #: what was published, stamped
        self._next_report = math.inf
        self._blocked_since: float | None = None
        self._latest: tuple[Pose, LaserScan] | None = None  #: the last scan and its pose
        #: (stamp, pose) of the last poses, oldest first
        self._poses: deque[tuple[float, Pose]] = deque(maxlen=POSE_HISTORY)
        #: scans newer than every pose so far, in arrival order
        self._waiting: deque[LaserScan] = deque()

    # -- inputs ---------------------------------------------------------------------------------
    def on_pose(self, msg: m.RobotPose2D) -> None:
        pose = (msg.x, msg.y, msg.theta)
        if not all(math.isfinite(v) for v in pose):
            self.stats["pose_dropped"] += 1
            log.warning("%s: dropped a RobotPose2D with NaN/inf %r", self.name, pose)
            return
        self.pose = pose
        stamp = float(msg.stamp)
        if self._poses and stamp < self._poses[-1][0]:
            self._poses.clear()  # time went back (a simulation started again)
            self._waiting.clear()
        self._poses.append((stamp, pose))
        if self._waiting:
            self._pair_waiting(stamp, pose)

    def _pair_waiting(self, stamp: float, pose: Pose) -> None:
        """The newest waiting scan ``pose`` (the first at or after its stamp) reaches."""
        reached = [s for s in self._waiting if s.stamp <= stamp]
        if not reached:
            return
        newest = max(reached, key=lambda s: s.stamp)
        self._waiting = deque(s for s in self._waiting if s.stamp > stamp)
        self.stats["scan_superseded"] += len(reached) - 1
        self._take_scan(pose, newest)

    def on_scan(self, msg: m.GLaserScan) -> None:
        if self.pose is None:
            return
        try:
            scan = laser_from_pb(msg)
        except m.TraceError as exc:
            self.stats["scan_dropped"] += 1
            log.warning("%s: dropped a scan: %s", self.name, exc)
            return
        if scan.stamp <= 0.0 or self._poses[-1][0] <= 0.0:  # unstamped: the latest pose
            self._take_scan(self.pose, scan)
            return
        poses = self._poses
        if scan.stamp < poses[0][0] and len(poses) == poses.maxlen:  # older than all kept
            self.stats["scan_too_old"] += 1
            n = self.stats["scan_too_old"]
            if worth_logging(n):
                log.warning("%s: dropped a scan %.2f s older than every pose kept (a busy "
                            "host; %d so far)", self.name, poses[0][0] - scan.stamp, n)
            return
        pose = next((p for t, p in poses if t >= scan.stamp), None)  # the pose of its time
        if pose is None:  # for the pose of its time
            if len(self._waiting) >= SCANS_WAITING:
                self._waiting.popleft()
                self.stats["scan_superseded"] += 1
            self._waiting.append(scan)
        else:
            self._take_scan(pose, scan)

    def _take_scan(self, pose: Pose, scan: LaserScan) -> None:
        self._latest = (pose, scan)
        if self.status == m.RUNNING:  # an idle module only keeps the latest scan
            self._use_scan()

    def _use_scan(self) -> None:
        if self._latest is None:
            return
        pose, scan = self._latest
        self.local.update(pose, scan)
        self.mark(pose, scan)

    def mark(self, pose: Pose, scan: LaserScan) -> None:
        """A subclass's extra costmap update from the same scan."""

    def on_route(self, msg: m.GTraceList) -> None:
        if not msg.lists:
            self.cancel()
            return
        if self.status == m.RUNNING:
            self._refuse(msg, "a list arrived while one runs: send an empty list first to "
                              "cancel it", m.RUNNING)
            return
        try:
            route = m.check_route(msg, self.params.map_name, self.extent)
        except m.TraceError as exc:
            self._refuse(msg, str(exc), m.IDLE)
            return
        self.accept(route)

    # -- outputs --------------------------------------------------------------------------------
    def speed(self, linear: float, angular: float) -> None:
        self._publish_speed(m.GRobotSpeedControl(linear=linear, angular=angular,
                                                 stamp=self.clock.now()))

    def report(self, status: int) -> None:
        assert self.route is not None
        msg = m.report(self.route, status, self.finished)
        self.reports.append((self.clock.now(), msg))
        self._publish(msg)

    def _refuse(self, msg: m.GTraceList, reason: str, status: int) -> None:
        self.stats["refused"] += 1
        log.warning("%s: refused a GTraceList: %s", self.name, reason)
        answer = m.report(self.route, status, self.finished) \
            if status == m.RUNNING and self.route is not None else m.report(msg, status)
        self.reports.append((self.clock.now(), answer))
        self._publish(answer)

    # -- the task -------------------------------------------------------------------------------
    def accept(self, route: m.Route) -> None:
        raise NotImplementedError

    def start(self, route: m.Route, finished: Sequence[float]) -> None:
        self.route = route
        self.finished = [float(f) for f in finished]
        self._use_scan()  # the costmaps start from what the laser sees now
        self.status = m.RUNNING
        self._blocked_since = None
        self.report(m.RUNNING)
        self._next_report = self.clock.now() + self.params.status_period

    def cancel(self) -> None:
        """An empty list: zero speed at once, IDLE, reported once."""
        self.speed(0.0, 0.0)
        self.ctl.set_plan([])
        self.ctl.v = self.ctl.w = 0.0
        self.status = m.IDLE
        self._next_report = math.inf
        msg = m.GTraceList(map=self.route.map if self.route else b"", status=m.IDLE)
        self.reports.append((self.clock.now(), msg))
        self._publish(msg)

    def end(self, status: int) -> None:
        """FINISHED (momentary: the module is IDLE after) or BLOCKED (persists); the robot is
        stopped and this module stops sending speed."""
        self.speed(0.0, 0.0)
        self.ctl.v = self.ctl.w = 0.0
        self.report(status)
        self.status = m.IDLE if status == m.FINISHED else status
        self._next_report = math.inf

    def tick(self) -> None:
        """One control period."""
        if self.status != m.RUNNING:
            return
        now = self.clock.now()
        if now + 1e-9 >= self._next_report:
            self.report(m.RUNNING)
            # on the grid of the acceptance time: a late tick skips the slots it missed
            # (one report, not a burst of them)
            period = self.params.status_period
            self._next_report += period * (1 + math.floor((now + 1e-9 - self._next_report)
                                                          / period))
        if self.pose is None:
            self.speed(0.0, 0.0)
            return
        self.ctl.set_costmap(self.local.costs, self.local.resolution, self.local.origin)
        self.step(self.pose)

    def step(self, pose: Pose) -> None:
        raise NotImplementedError

    def drive(self, speed: float, pose: Pose) -> Command:
        """One controller period at ``speed`` [m/s]; the command is published."""
        v = min(max(speed, self.ctl.config.min_speed), self.limits.max_linear)
        if v != self.ctl.config.max_speed:
            self.ctl.config = replace(self.ctl.config, max_speed=v)
        cmd = self.ctl.compute(pose)
        self.speed(cmd.linear, cmd.angular)
        now = self.clock.now()
        if cmd.status is Status.BLOCKED:
            self._blocked_since = now if self._blocked_since is None else self._blocked_since
        else:
            self._blocked_since = None
        return cmd

    @property
    def blocked_for(self) -> float:
        """[s] the controller has been stopped by an obstacle (0 when it is not)."""
        return 0.0 if self._blocked_since is None else self.clock.now() - self._blocked_since


def sample_segment(seg: m.Segment, t0: float, step: float) -> np.ndarray:
    """(n, 3) poses from fraction ``t0`` to the end every ``step`` m, facing along."""
    n = max(1, math.ceil(seg.length * (1.0 - t0) / step))
    t = np.linspace(t0, 1.0, n + 1)
    out = np.empty((t.size, 3))
    out[:, 0] = seg.x0 + t * (seg.x1 - seg.x0)
    out[:, 1] = seg.y0 + t * (seg.y1 - seg.y0)
    out[:, 2] = seg.heading
    return out
