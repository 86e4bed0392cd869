"""Driving a WorldSim with the path controller at 20 Hz through driver_base's set_twist (the
real chain: driver core -> bus frames -> emulator), for the navigation tests."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from lowerbase.navigation.controller import Command, PathController, Status
from lowerbase.navigation.navigator import Navigator, NavigatorConfig
from lowerbase.navigation.sim import NavSim
from lowerbase.world.obstacles import Box, obstacles_from_dicts
from lowerbase.world.sim import WorldConfig, WorldSim


@dataclass
class Run:
    commands: list[Command] = field(default_factory=list)
    contacts: int = 0
    status: Status = Status.IDLE


def follow(sim: WorldSim, ctl: PathController, timeout: float, settle: float = 1.0,
           patience: float = 1.0) -> Run:
    """Tick the controller every 50 ms on the localization estimate (movebase_pose2d) until
    it SUCCEEDS or stays BLOCKED for ``patience`` s (then keep ticking for ``settle`` s), or
    ``timeout``."""
    run = Run()
    every = round(0.05 / sim.loop.mcu.dt)
    end = sim.now + timeout
    stop_at = None
    blocked_since = None
    while sim.now < end and (stop_at is None or sim.now < stop_at):
        pose = sim.amcl_pose()
        assert pose is not None
        cmd = ctl.compute(pose)
        run.commands.append(cmd)
        run.status = cmd.status
        sim.loop.driver.set_twist(cmd.linear, cmd.angular)
        blocked = cmd.status is Status.BLOCKED
        blocked_since = (blocked_since if blocked_since is not None else sim.now) \
            if blocked else None
        if stop_at is None and (cmd.status is Status.SUCCEEDED or (
                blocked_since is not None and sim.now - blocked_since >= patience)):
            stop_at = sim.now + settle
        for _ in range(every):
            sim.step()
            run.contacts += sim.contact is not None
    return run


# -- the Navigator on a WorldSim (tests/navigation/test_navigator*.py) ------------------------

def nav_world(map_name: str, start: tuple[float, float, float] | str,
              obstacles: list[dict[str, object]] | None = None, localization: str = "truth",
              config: NavigatorConfig | None = None) -> NavSim:
    """A NavSim on ``map_name`` with the driver up and odometry running."""
    world = WorldSim(WorldConfig(map=map_name, start=start, localization=localization,
                                 obstacles=obstacles_from_dicts(obstacles or [])))
    world.run(1.0)
    return NavSim(world, Navigator(world.grid, config))


def box(name: str, x: float, y: float, size: float = 0.6) -> Box:
    return Box(name, (x, y), (size, size))


def distance_to(path: list[tuple[float, float, float]], x: float, y: float) -> float:
    """The nearest the robot's centre came to (x, y)."""
    return min(math.hypot(p[0] - x, p[1] - y) for p in path)
