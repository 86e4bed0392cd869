"""A Navigator driving a WorldSim on the simulated clock: :class:`NavSim`.

Every control period (20 Hz) the navigator gets the localization estimate (movebase_pose2d:
/odom through map -> odom, :meth:`WorldSim.amcl_pose`) and answers a twist, sent as
/base_cmd_vel through driver_base's core (``sim.loop.driver.set_twist``), the bus and the
emulator: the whole chain and every lower-computer rule applies. The local costmap is updated at
``sensor_rate`` (move_base's local ``update_frequency``, 5 Hz) from the merged /scan and, with
the camera on, its cloud_without_planes. While no goal is active nothing is sent (one zero twist
when a goal ends), so other commanders (StepControl, a test) can drive.

Standing idle costs no sensing: while no goal is pending or active, the camera is off and the
estimate has not moved since the last update (``idle_still``: 1 mm, 0.05 deg), the 5 Hz update
is deferred: no scan is cast for it (:meth:`WorldSim.skip_scan` draws its noise, so every other
scan stays what it was) and no costmap work is done. The next tick that needs the costmap (a
goal pending or active, or the robot moving) first does the last deferred update, with the same
scan and pose. Nothing reads the local costmap meanwhile, and a standing robot's repeated updates
only re-mark the same returns: the robot drives exactly as with every update done
(``idle_sensing=True``; tests/navigation/test_navsim_idle.py compares both, tick by tick).

:meth:`NavSim.go_to` is what tests, scenarios and benchmarks use: send a goal and run until it
ends, answering a :class:`NavRun` (state, reason, time, the true path driven, contacts, the
largest speed commanded and driven).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

from lowerbase.navigation.controller import Limits, wrap
from lowerbase.navigation.costmap import camera_cloud
from lowerbase.navigation.navigator import GoalState, NavCommand, Navigator, Pose
from lowerbase.simloop.loop import TickedLoop
from lowerbase.world.lidar import LaserScan
from lowerbase.world.obstacles import Obstacle
from lowerbase.world.sim import DeferredScan, WorldSim

CONTROL_PERIOD = 0.05


@dataclass
class NavRun:
    """What one goal did: final ``state`` and ``reason``, ``duration`` [s] of simulated time,
    the true ``path`` driven (map poses every control period), steps in ``contact`` with
    anything, the largest ``max_commanded`` and ``max_driven`` linear speeds [m/s] (driven:
    from the true path)."""

    state: GoalState
    reason: str = ""
    duration: float = 0.0
    path: list[Pose] = field(default_factory=list)
    stamps: list[float] = field(default_factory=list)
    commands: list[NavCommand] = field(default_factory=list)
    contacts: int = 0
    max_commanded: float = 0.0

    @property
    def max_driven(self) -> float:
        """The largest true speed over one control period (a 3-period mean) [m/s]."""
        best = 0.0
        for i in range(3, len(self.path)):
            (x0, y0, _), (x1, y1, _) = self.path[i - 3], self.path[i]
            dt = self.stamps[i] - self.stamps[i - 3]
            if dt > 0:
                best = max(best, math.hypot(x1 - x0, y1 - y0) / dt)
        return best

    @property
    def length(self) -> float:
        return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in
                   zip(self.path[:-1], self.path[1:], strict=True))


class NavSim(TickedLoop):
    """A Navigator ticked at 20 Hz on a WorldSim (see the module docstring)."""

    def __init__(self, world: WorldSim, navigator: Navigator | None = None,
                 sensor_rate: float = 5.0, idle_sensing: bool = False,
                 idle_still: tuple[float, float] = (1e-3, math.radians(0.05))) -> None:
        self.world = world
        self.idle_sensing = idle_sensing
        self.idle_still = idle_still
        self._sensed_at: Pose | None = None  #: the pose of the last local costmap update
        #: the last update deferred while standing idle: (pose, scan)
        self._deferred: tuple[Pose, DeferredScan | None] | None = None
        self.navigator = navigator or Navigator(world.grid, footprint=world.config.footprint)
        self.navigator.set_limits(Limits.from_parameters(world.loop.driver.parameters))
        self._every = max(1, round(CONTROL_PERIOD / world.control_dt))
        self._sensor_period = 1.0 / sensor_rate
        self._next_sensor = world.now
        self._was_active = False
        self.contacts = 0  #: control steps with a contact since the start
        self.last: NavCommand | None = None

    @property
    def now(self) -> float:
        return self.world.now

    def pose(self) -> Pose:
        """The localization estimate the navigator closes the loop on (the truth until the
        driver has /odom)."""
        est = self.world.amcl_pose()
        return est if est is not None else self.world.true_pose()

    def set_obstacles(self, items: Iterable[Obstacle]) -> None:
        """Replace the world's obstacles from now on (a box dropped or taken away): the
        sensors and the contact check see the new set at once."""
        self.world.obstacles.replace(items)

    def tick(self) -> NavCommand:
        """One control period: sensors if due, the navigator, the twist, the world."""
        w, nav = self.world, self.navigator
        pose = self.pose()
        idle = nav.state not in (GoalState.PENDING, GoalState.ACTIVE)
        if w.now + 1e-9 >= self._next_sensor:
            self._next_sensor += self._sensor_period
            if idle and w.camera is None and self._standing(pose):
                self._deferred = (pose, w.skip_scan())
            else:
                self._sense(pose)
        elif self._deferred is not None and not (idle and self._standing(pose)):
            d_pose, d_scan = self._deferred  # catch up before the costmap is used
            self._sense(d_pose, None if d_scan is None else w.deferred_scan(d_scan))
        cmd = nav.tick(w.now, pose)
        active = cmd.state in (GoalState.PENDING, GoalState.ACTIVE)
        if active or self._was_active:
            w.loop.driver.set_twist(cmd.linear, cmd.angular)
        self._was_active = active
        self.last = cmd
        self.contacts += w.run_periods(self._every)
        return cmd

    def _standing(self, pose: Pose) -> bool:
        """The estimate has not moved since the last costmap update (``idle_sensing``: never
        treated as standing)."""
        ref = self._sensed_at
        if self.idle_sensing or ref is None:
            return False
        d, a = self.idle_still
        return math.hypot(pose[0] - ref[0], pose[1] - ref[1]) <= d and \
            abs(wrap(pose[2] - ref[2])) <= a

    def _sense(self, pose: Pose, scan: LaserScan | bool | None = True) -> None:
        """One local costmap update from ``scan`` (True: the latest scan) and the camera."""
        w = self.world
        cloud = None
        if w.camera is not None and w.frame is not None:
            cloud = camera_cloud(w.frame.points_without_planes, w.camera.config)
        use = w.scan if scan is True else scan if isinstance(scan, LaserScan) else None
        self.navigator.update_sensors(pose, scan=use, cloud=cloud)
        self._sensed_at = (float(pose[0]), float(pose[1]), float(pose[2]))
        self._deferred = None

    def go_to(self, target: Sequence[float], timeout: float = 120.0,
              poses: Sequence[Sequence[float]] = (), execution_mode: int = 0,
              during: Callable[[NavSim, NavRun], None] | None = None) -> NavRun:
        """Send a goal and tick until it ends or ``timeout`` s pass (then it is cancelled and
        the run says PREEMPTED, "timeout"). ``during(navsim, run)`` is called every period
        (drop a box, press the e-stop)."""
        nav = self.navigator
        nav.send_goal(target, poses, execution_mode, now=self.now)
        goal_id = nav.goal_id
        run = NavRun(GoalState.PENDING)
        t0 = self.now
        end = t0 + timeout
        while True:
            if during is not None:
                during(self, run)
            contacts = self.contacts
            cmd = self.tick()
            run.commands.append(cmd)
            run.contacts += self.contacts - contacts
            run.max_commanded = max(run.max_commanded, abs(cmd.linear))
            run.path.append(self.world.true_pose())
            run.stamps.append(self.now)
            if nav.goal_id != goal_id or cmd.state.terminal:
                break
            if self.now >= end:
                nav.cancel(self.now)
                self.tick()  # the zero twist
                run.state, run.reason, run.duration = GoalState.PREEMPTED, "timeout", \
                    self.now - t0
                return run
        result = next((r for r in nav.results if r.goal_id == goal_id), None)
        run.state = result.state if result is not None else cmd.state
        run.reason = result.reason if result is not None else cmd.reason
        run.duration = self.now - t0
        return run
