"""The path controller on the simulated clock through the real chain: WorldSim (emulator +
driver_base core + world, ground-truth localization) driven at 20 Hz via driver.set_twist.
Accuracy is checked on the localization estimate the controller closes the loop on
(movebase_pose2d: /odom through map -> odom) and on the emulator's ground truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.errors import ConfigError
from lowerbase.navigation.controller import ControllerConfig, Limits, PathController, Status, wrap
from lowerbase.navigation.planner import GlobalPlanner
from lowerbase.world.footprint import contact
from lowerbase.world.obstacles import obstacles_from_dicts
from lowerbase.world.sim import WorldConfig, WorldSim
from tests.navigation.costs import PADDED, inflate
from tests.navigation.drive import follow

Pose = tuple[float, float, float]


def _world(map_name: str, start: Pose, obstacles: list[dict[str, object]] | None = None
           ) -> WorldSim:
    sim = WorldSim(WorldConfig(map=map_name, start=start, localization="truth",
                               obstacles=obstacles_from_dicts(obstacles or [])))
    sim.run(1.0)  # driver configured, odometry running
    return sim


def _errors(pose: Pose, goal: Pose) -> tuple[float, float]:
    return math.hypot(pose[0] - goal[0], pose[1] - goal[1]), abs(wrap(pose[2] - goal[2]))


def _setup(sim: WorldSim, obstacles_in_costmap: bool = False
           ) -> tuple[GlobalPlanner, PathController]:
    costs = inflate(sim.grid)
    planner = GlobalPlanner(costs, sim.grid.resolution, footprint=PADDED.points)
    local = inflate(sim.obstacles.merged(sim.grid, sim.now)) if obstacles_in_costmap else costs
    ctl = PathController(local, sim.grid.resolution, footprint=PADDED.points,
                         limits=Limits.from_parameters(sim.loop.driver.parameters))
    return planner, ctl


@pytest.mark.parametrize("start, goal", [
    ((5.0, 4.0, 0.0), (8.0, 6.0, 0.0)),
    ((5.0, 4.0, 0.0), (2.0, 4.0, math.pi)),  # behind: rotate in place first
    ((2.5, 2.0, 1.0), (7.3, 5.9, -2.5)),
])
def test_reaches_goals_within_5cm_2deg_in_the_empty_room(start: Pose, goal: Pose) -> None:
    sim = _world("empty_room", start)
    planner, ctl = _setup(sim)
    plan = planner.make_plan(sim.amcl_pose(), goal)  # type: ignore[arg-type]
    ctl.set_plan(plan.poses)
    run = follow(sim, ctl, timeout=60.0)
    assert run.status is Status.SUCCEEDED
    est = sim.amcl_pose()
    assert est is not None
    d, a = _errors(est, goal)
    assert d <= 0.05 and a <= math.radians(2.0)
    d, a = _errors(sim.true_pose(), goal)  # the truth too (odometry error is small here)
    assert d <= 0.05 and a <= math.radians(2.0)
    assert run.contacts == 0
    assert run.commands[-1].linear == run.commands[-1].angular == 0.0


def test_commands_stay_within_the_chassis_limits() -> None:
    sim = _world("empty_room", (5.0, 4.0, 0.0))
    planner, ctl = _setup(sim)
    lim = ctl.limits
    assert lim == Limits(1.2, 1.0, 0.8, 1.0, 1.5, 2.0) or lim.max_linear == pytest.approx(1.2)
    ctl.set_plan(planner.make_plan(sim.amcl_pose(), (1.5, 6.5, 2.0)).poses)  # type: ignore
    run = follow(sim, ctl, timeout=60.0)
    assert run.status is Status.SUCCEEDED
    v = np.array([0.0] + [c.linear for c in run.commands])
    w = np.array([0.0] + [c.angular for c in run.commands])
    dt, eps = ctl.config.period, 1e-9
    assert np.abs(v).max() <= lim.max_linear and np.abs(w).max() <= lim.max_angular
    assert np.abs(np.diff(v)).max() <= max(lim.linear_accel, lim.linear_decel) * dt + eps
    assert np.abs(np.diff(w)).max() <= max(lim.angular_accel, lim.angular_decel) * dt + eps
    assert np.abs(v).max() > 0.3  # it did cruise


def test_drives_around_the_warehouse_racks_without_contact() -> None:
    sim = _world("warehouse", (4.0, 4.0, 0.0))
    planner, ctl = _setup(sim)
    goal = (21.0, 9.75, 3.0)  # between the racks of block B
    plan = planner.make_plan(sim.amcl_pose(), goal)  # type: ignore[arg-type]
    ctl.set_plan(plan.poses)
    run = follow(sim, ctl, timeout=120.0)
    assert run.status is Status.SUCCEEDED and run.contacts == 0
    d, a = _errors(sim.true_pose(), goal)
    assert d <= 0.05 and a <= math.radians(2.0)
    assert contact(sim.true_pose(), sim.grid, footprint=PADDED) is None


def test_obstacle_on_the_path_stops_the_robot_before_contact() -> None:
    box: dict[str, object] = {"kind": "box", "name": "crate", "center": [7.5, 4.0],
                              "size": [0.6, 1.2]}
    sim = _world("empty_room", (3.0, 4.0, 0.0), [box])
    planner, ctl = _setup(sim, obstacles_in_costmap=True)
    # the global plan does not know the crate (static map only): it runs straight through it
    ctl.set_plan(planner.make_plan(sim.amcl_pose(), (9.0, 4.0, 0.0)).poses)  # type: ignore
    run = follow(sim, ctl, timeout=40.0, settle=2.0)
    assert run.status is Status.BLOCKED and "obstacle" in run.commands[-1].reason
    assert run.contacts == 0 and sim.contact is None
    x = sim.true_pose()[0]
    assert 7.2 - 0.5 - 0.6 < x < 7.2 - 0.5  # stopped short of the crate's face (x 7.2)
    assert abs(sim.loop.mcu.truth.v) < 1e-3  # standing still
    assert max(c.linear for c in run.commands) > 0.3  # it was moving when it saw the crate


def test_bad_configuration_is_refused() -> None:
    with pytest.raises(ConfigError, match="max_linear"):
        Limits(max_linear=float("nan"))
    with pytest.raises(ConfigError, match="xy_tolerance"):
        ControllerConfig(xy_tolerance=0.0)
    ctl = PathController(np.zeros((10, 10), np.uint8), 0.1, footprint=PADDED.points)
    with pytest.raises(ConfigError, match="finite"):
        ctl.set_plan([(0.0, float("nan"), 0.0)])
    assert ctl.compute((0.0, 0.0, 0.0)).status is Status.IDLE
