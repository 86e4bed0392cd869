"""A Navigator driving a WorldSim on the simulated clock: :class:`NavSim`.

Every control period (20 Hz) the navigator gets the localization estimate (movebase_pose2d:
/odom through map -> odom, :meth:`WorldSim.amcl_pose`) and answers a twist, sent as
/base_cmd_vel through driver_base's core (``sim.loop.driver.set_twist``), the bus and the
emulator: the whole chain and every lower-computer rule applies. The local costmap is updated at
``sensor_rate`` (move_base's local ``update_frequency``, 5 Hz) from the merged /scan and, with
the camera on, its cloud_without_planes. While no goal is active nothing is sent (one zero twist
when a goal ends), so other commanders (StepControl, a test) can drive.

:meth:`NavSim.go_to` is what tests, scenarios and benchmarks use: send a goal and run until it
ends, answering a :class:`NavRun` (state, reason, time, the true path driven, contacts, the
largest speed commanded and driven).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

from lowerbase.navigation.controller import Limits
from lowerbase.navigation.costmap import camera_cloud
from lowerbase.navigation.navigator import GoalState, NavCommand, Navigator, Pose
from lowerbase.world.obstacles import Obstacle, Obstacles
from lowerbase.world.sim import WorldSim

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


class NavSim:
    """A Navigator ticked at 20 Hz on a WorldSim (see the module docstring)."""

    def __init__(self, world: WorldSim, navigator: Navigator | None = None,
                 sensor_rate: float = 5.0) -> None:
        self.world = world
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
        self.world.obstacles.items = Obstacles(items).items

    def tick(self) -> NavCommand:
        """One control period: sensors if due, the navigator, the twist, the world."""
        w, nav = self.world, self.navigator
        pose = self.pose()
        if w.now + 1e-9 >= self._next_sensor:
            self._next_sensor += self._sensor_period
            cloud = None
            if w.camera is not None and w.frame is not None:
                cloud = camera_cloud(w.frame.points_without_planes, w.camera.config)
            nav.update_sensors(pose, scan=w.scan, cloud=cloud)
        cmd = nav.tick(w.now, pose)
        active = cmd.state in (GoalState.PENDING, GoalState.ACTIVE)
        if active or self._was_active:
            w.loop.driver.set_twist(cmd.linear, cmd.angular)
        self._was_active = active
        self.last = cmd
        for _ in range(self._every):
            w.step()
            self.contacts += w.contact is not None
        return cmd

    def run(self, seconds: float) -> None:
        """Tick for ``seconds`` of simulated time."""
        end = self.now + seconds
        while self.now < end - 1e-9:
            self.tick()

    def run_until(self, condition: Callable[[NavSim], bool], timeout: float) -> bool:
        end = self.now + timeout
        while self.now < end - 1e-9:
            if condition(self):
                return True
            self.tick()
        return condition(self)

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
