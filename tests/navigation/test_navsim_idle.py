"""NavSim skips the local costmap's updates while standing idle (no scan cast for them): the
robot's trajectory and the task machine's states are exactly those of a NavSim that updates at
every sensor period (``idle_sensing=True``, the reference), while a crate is dropped beside the
standing robot and taken away again, and while tasks stand for loading."""

from __future__ import annotations

from lowerbase.navigation.sim import NavSim
from lowerbase.simloop.loop import SimLoop
from lowerbase.tasks.model import TaskRequest, TaskType
from lowerbase.tasks.plan import TaskConfig
from lowerbase.tasks.sim import TaskSim
from lowerbase.world.obstacles import Box
from lowerbase.world.sim import WorldConfig, WorldSim

Trace = list[tuple[object, ...]]


def shift(idle_sensing: bool) -> tuple[Trace, int, int]:
    world = WorldSim(WorldConfig(map="warehouse", start="start"), loop=SimLoop(soc=80.0))
    nav = NavSim(world, idle_sensing=idle_sensing)
    ts = TaskSim(nav, config=TaskConfig(load_time=3.0, unload_time=3.0))
    trace: Trace = []

    def tick() -> None:
        ts.tick()
        cur = ts.machine.tracker.current
        state = None if cur is None else (cur.task_id, cur.task_state, cur.action_type)
        trace.append((world.true_pose(), world.amcl_pose(), state, nav.last))

    for _ in range(60):  # stand 3 s
        tick()
    nav.set_obstacles([Box("crate", (5.0, 3.2), (0.4, 0.4))])  # beside the standing robot
    for _ in range(40):
        tick()
    nav.set_obstacles([])
    for _ in range(20):
        tick()
    for task_id, mark in ((1, "A1-01"), (2, "A2-01")):
        ts.request(TaskRequest(1, task_id, TaskType.TRANSPORTING, 1, mark_no=mark))
        while ts.machine.active:
            tick()
        for _ in range(40):  # idle between tasks
            tick()
    return trace, world.scans, nav.navigator.local_costmap.stats.updates


def test_standing_idle_skips_the_sensing_and_changes_nothing_the_robot_does() -> None:
    ref, ref_scans, ref_updates = shift(idle_sensing=True)
    new, new_scans, new_updates = shift(idle_sensing=False)
    assert len(new) == len(ref) > 400
    assert new == ref  # poses, estimates, task states, navigator commands: every tick
    assert new_scans < ref_scans and new_updates < ref_updates
