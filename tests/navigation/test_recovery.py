"""The recoveries on hand-made cost grids: the back-off backs off the way the robot came while
that stays clear, also when the footprint already touches a lethal cell ahead, and stops at its
distance or when the way back is blocked too; the turn in place turns a full turn, stopping
before its sweep touches a lethal cell; the conservative costmap reset forgets only the marks
beyond its square; a navigator runs them in move_base's order between blocked replans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.navigation.controller import Command, Status
from lowerbase.navigation.costmap import local_costmap
from lowerbase.navigation.layers import Observation
from lowerbase.navigation.modes import NavigationModeGoal
from lowerbase.navigation.navigator import (
    GoalState,
    NavigationError,
    Navigator,
    NavigatorConfig,
)
from lowerbase.navigation.planner import LETHAL, FootprintCells
from lowerbase.navigation.recovery import BackOff, BackOffConfig, Rotate, RotateConfig
from lowerbase.world.footprint import DEFAULT_POINTS
from lowerbase.world.grid import OccupancyGrid

RES = 0.05


def grid(wall_x: list[float]) -> np.ndarray:
    costs = np.zeros((100, 100), np.uint8)  # 5 x 5 m, origin (0, 0)
    for x in wall_x:
        costs[:, int(x / RES)] = LETHAL
    return costs


FP = FootprintCells([(float(x), float(y)) for x, y in DEFAULT_POINTS], RES)


def room_grid() -> OccupancyGrid:
    """An empty 10 x 10 m room with walls round it."""
    data = np.zeros((200, 200), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    return OccupancyGrid(data, RES, (0.0, 0.0, 0.0))


def test_backs_off_from_a_wall_it_touches_and_stops_after_the_distance() -> None:
    costs = grid([2.8])  # the footprint's front (0.4 m) reaches it from x = 2.4
    pose = (2.4, 2.5, 0.0)
    assert FP.max_cost(costs, (0.0, 0.0), *pose)[0] >= LETHAL  # wedged
    b = BackOff(BackOffConfig(distance=0.3, speed=0.1))
    b.begin(pose, 0.0, reversed_driving=False)
    assert b.step(pose, 0.05, costs, (0.0, 0.0), FP) == pytest.approx(-0.1)
    assert b.step((2.25, 2.5, 0.0), 1.5, costs, (0.0, 0.0), FP) == pytest.approx(-0.1)
    assert b.step((2.09, 2.5, 0.0), 3.0, costs, (0.0, 0.0), FP) is None  # 0.31 m: done
    assert not b.active


def test_does_not_back_into_a_wall_behind() -> None:
    costs = grid([2.8, 1.85])
    b = BackOff()
    b.begin((2.4, 2.5, 0.0), 0.0, reversed_driving=False)
    assert b.step((2.4, 2.5, 0.0), 0.05, costs, (0.0, 0.0), FP) is None


def test_drives_forward_when_the_robot_was_reversing_and_gives_up_on_timeout() -> None:
    costs = grid([])
    b = BackOff(BackOffConfig(timeout=2.0))
    b.begin((2.5, 2.5, 0.0), 10.0, reversed_driving=True)
    assert b.step((2.5, 2.5, 0.0), 10.05, costs, (0.0, 0.0), FP) == pytest.approx(0.1)
    assert b.step((2.5, 2.5, 0.0), 12.0, costs, (0.0, 0.0), FP) is None  # wheels slipping


def test_rotate_turns_a_full_turn_in_open_space() -> None:
    costs = grid([])
    r = Rotate(RotateConfig(speed=0.5))
    r.begin((2.5, 2.5, 3.0), 0.0)
    yaw, t, commands = 3.0, 0.0, 0
    while True:
        w = r.step((2.5, 2.5, yaw), t, costs, (0.0, 0.0), FP)
        if w is None:
            break
        assert w == pytest.approx(0.5)
        commands += 1
        yaw = (yaw + w * 0.05 + math.pi) % (2 * math.pi) - math.pi  # across the +-pi seam
        t += 0.05
    assert 2 * math.pi - 0.05 <= commands * 0.5 * 0.05 <= 2 * math.pi + 0.05
    assert r.count == 1 and not r.active


def test_rotate_stops_before_its_sweep_touches_a_lethal_cell() -> None:
    costs = grid([])
    costs[:, :] = 0
    costs[54:56, 52:57] = LETHAL  # a post just clear of the footprint's left side
    pose = (2.5, 2.3, 0.0)
    assert FP.max_cost(costs, (0.0, 0.0), *pose)[0] < LETHAL  # clear where it stands
    r = Rotate()
    r.begin(pose, 0.0)
    yaw, stopped = 0.0, None
    for k in range(400):
        w = r.step((2.5, 2.3, yaw), 0.05 * k, costs, (0.0, 0.0), FP)
        if w is None:
            stopped = yaw
            break
        yaw += w * 0.05
    assert stopped is not None and stopped < math.pi  # it did not turn into the post
    assert FP.max_cost(costs, (0.0, 0.0), 2.5, 2.3, stopped)[0] < LETHAL


def test_clear_outside_forgets_marks_beyond_the_square_only() -> None:
    cm = local_costmap(None, (0.0, 0.0, 0.0))
    layer = cm.obstacle_layer
    assert layer is not None
    m = layer.map
    near = m.world_to_map(np.array([0.5]), np.array([-0.6]))
    far = m.world_to_map(np.array([2.2]), np.array([1.9]))
    for c, r in (near, far):
        m.data[r, c] = 254
    assert cm.clear_outside(0.0, 0.0, 3.0) == 1
    assert m.data[near[1], near[0]][0] == 254 and m.data[far[1], far[0]][0] == m.default
    assert cm.costs[near[1], near[0]][0] == 254  # the master grid rebuilt


def test_recoveries_run_in_move_base_s_order_between_blocked_replans() -> None:
    """A navigator whose controller never gets through: the first blocked replan at once, then
    back off, the conservative reset (a far mark forgotten, a near one kept), a full turn, the
    aggressive reset (every mark forgotten), then ABORTED after max_replans."""
    nav = Navigator(room_grid(), NavigatorConfig())
    blocked = Command(0.0, 0.0, Status.BLOCKED, "test: an obstacle ahead")
    nav.controller.compute = lambda pose: blocked  # type: ignore[method-assign]
    pose = (2.0, 2.0, 0.0)
    nav.update_sensors(pose)
    layer = nav.local_costmap.obstacle_layer
    assert layer is not None
    m = layer.map
    near = m.world_to_map(np.array([2.6]), np.array([2.0]))
    far = m.world_to_map(np.array([4.2]), np.array([3.9]))
    for c, r in (near, far):
        m.data[r, c] = 254
    nav.send_goal((7.0, 7.0, 0.0), now=0.0)
    seen: list[tuple[str, bool, bool]] = []
    t, state = 0.0, None
    while t < 400.0:
        cmd = nav.tick(t, pose)
        state = cmd.state
        if cmd.state.terminal:
            break
        if len(seen) < len(nav._recovery.log):
            seen.append((nav._recovery.log[-1], bool(m.data[near[1], near[0]][0] == 254),
                         bool(m.data[far[1], far[0]][0] == 254)))
        if cmd.reason.startswith("recovery"):
            assert cmd.status is Status.BLOCKED
        t += 0.05
    assert state is GoalState.ABORTED and "replans" in nav.reason
    assert seen == [("back_off", True, True), ("clear_conservative", True, False),
                    ("rotate", True, False), ("clear_aggressive", False, False)]
    assert nav._recovery.rotate.count == 1 and nav._recovery.back_off.count == 1


def mark(nav: Navigator, pose: tuple[float, float, float], points: list[tuple[float, float]]
         ) -> None:
    """Marks at map ``points`` in the navigator's local costmap (an observation that only
    marks: they stay, as marks no ray clears)."""
    pts = np.array([(x, y, 0.1) for x, y in points])
    nav.local_costmap.update_observations(pose, [Observation((pose[0], pose[1], 0.2), pts,
                                                             clearing=False)])
    nav.combined.refresh()


def test_backs_off_forwards_when_the_way_back_is_blocked() -> None:
    costs = grid([1.85])  # a wall just behind: backing 0.3 m would touch it
    b = BackOff()
    b.begin((2.4, 2.5, 0.0), 0.0, reversed_driving=False)
    assert b.step((2.4, 2.5, 0.0), 0.05, costs, (0.0, 0.0), FP) == pytest.approx(0.1)
    assert b.flipped == 1 and not b.blocked
    assert b.step((2.5, 2.5, 0.0), 1.0, costs, (0.0, 0.0), FP) == pytest.approx(0.1)


def test_back_off_keeps_the_body_off_lethal_cells_not_the_padding() -> None:
    """A wall 0.36 m beside the centre line: inside the padded footprint's sweep, clear of the
    robot's own (0.3 m half-width): the back-off checked on the body moves."""
    costs = np.zeros((100, 100), np.uint8)
    costs[int(2.86 / RES), :] = LETHAL  # a wall along x at y = 2.86
    padded = FootprintCells([(1.2 * x, 1.2 * y) for x, y in DEFAULT_POINTS], RES)
    pose = (2.5, 2.5, 0.0)
    assert padded.max_cost(costs, (0.0, 0.0), *pose)[0] >= LETHAL
    assert FP.max_cost(costs, (0.0, 0.0), *pose)[0] < LETHAL
    b = BackOff()
    b.begin(pose, 0.0, reversed_driving=False)
    assert b.step(pose, 0.05, costs, (0.0, 0.0), padded) is None and b.blocked
    b.begin(pose, 0.0, reversed_driving=False)
    assert b.step(pose, 0.05, costs, (0.0, 0.0), padded, body=FP) == pytest.approx(-0.1)


def test_both_ways_blocked_by_stale_marks_clears_around_and_re_senses() -> None:
    """Marks just ahead of and behind the robot that no scan sees any more: the back-off finds
    both ways blocked, forgets the marks around the robot, waits for the next sensor update
    (standing still) and then backs off."""
    nav = Navigator(room_grid(), NavigatorConfig())
    nav.set_mode(NavigationModeGoal(navigation_mode=0))  # keep-out 0.5 m: the start is free
    blocked = Command(0.0, 0.0, Status.BLOCKED, "test: an obstacle ahead")
    nav.controller.compute = lambda pose: blocked  # type: ignore[method-assign]
    pose = (5.0, 5.0, 0.0)
    nav.update_sensors(pose)
    nav.send_goal((5.0, 8.0, 0.0), now=0.0)
    # 0.15 m beyond the padded footprint's back and front (the body's: 0.25 m)
    mark(nav, pose, [(x, y) for x in (4.35, 5.65) for y in (4.9, 5.0, 5.1)])
    commands = [nav.tick(0.05 * k, pose) for k in range(80)]  # 4 s, no sensor update
    assert nav._recovery.log[:2] == ["back_off", "clear_around"], nav._recovery.log
    assert all(c.linear == 0.0 and c.angular == 0.0 for c in commands)
    assert commands[-1].reason.startswith("recovery: backing")  # waiting for a scan
    nav.update_sensors(pose)  # the next scan: nothing there
    cmd = nav.tick(4.0, pose)
    assert cmd.linear == pytest.approx(-0.1) and cmd.reason.startswith("recovery: backing")


def test_recovery_behaviors_are_configurable_and_checked() -> None:
    nav = Navigator(room_grid(), NavigatorConfig(recovery_behaviors=("clear_aggressive",
                                                                     "rotate")))
    assert [nav._recovery.pick(n, False) for n in (1, 2, 3, 4)] == \
        ["", "clear_aggressive", "rotate", "rotate"]
    assert nav._recovery.pick(3, True) == "back_off"
    with pytest.raises(NavigationError, match="unknown 'spin'"):
        NavigatorConfig(recovery_behaviors=("back_off", "spin"))
    with pytest.raises(NavigationError, match="non-empty"):
        NavigatorConfig(recovery_behaviors=())


def test_no_plan_because_of_stale_marks_resets_the_local_costmap_and_plans_again() -> None:
    """A mark whose keep-out covers the goal (something gone, or marked with a heading error):
    the plan fails, the local obstacle layer is reset, the second plan succeeds."""
    nav = Navigator(room_grid(), NavigatorConfig())
    pose = (3.0, 5.0, 0.0)
    nav.update_sensors(pose)
    mark(nav, pose, [(5.0, 5.3)])
    assert not nav.make_plan(pose, (5.0, 5.0, 0.0)).ok  # the mark's keep-out covers the goal
    nav.send_goal((5.0, 5.0, 0.0), now=0.0)
    cmd = nav.tick(0.0, pose)
    assert cmd.state is GoalState.ACTIVE, cmd.reason
    assert nav._recovery.log == ["clear_for_plan"] and nav.path
    m = nav.local_costmap.obstacle_layer.map  # type: ignore[union-attr]
    assert not (m.data == 254).any()
    off = Navigator(room_grid(), NavigatorConfig(clear_on_no_path=False))
    off.update_sensors(pose)
    mark(off, pose, [(5.0, 5.3)])
    off.send_goal((5.0, 5.0, 0.0), now=0.0)
    assert off.tick(0.0, pose).state is GoalState.ABORTED


def test_rotate_turns_clockwise_when_only_that_way_has_room() -> None:
    costs = grid([])
    costs[int((2.5 + 0.36) / RES), int((2.5 + 0.38) / RES)] = LETHAL  # by the front-left corner
    pose = (2.5, 2.5, 0.0)
    assert FP.max_cost(costs, (0.0, 0.0), *pose)[0] < LETHAL
    assert FP.max_cost(costs, (0.0, 0.0), 2.5, 2.5, 0.15)[0] >= LETHAL  # no room to the left
    r = Rotate()
    r.begin(pose, 0.0)
    assert r.step(pose, 0.05, costs, (0.0, 0.0), FP) == pytest.approx(-0.5)
    assert r.step((2.5, 2.5, -0.1), 0.25, costs, (0.0, 0.0), FP) == pytest.approx(-0.5)
    assert r.clockwise == 1 and not r.blocked
