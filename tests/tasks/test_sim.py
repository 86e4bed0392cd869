"""Tasks on the whole emulated robot (emulator, driver core, warehouse, localization, navigator)
on the simulated clock, checked against the emulator's ground truth."""

from __future__ import annotations

import math

import pytest

from lowerbase.navigation.sim import NavSim
from lowerbase.simloop.loop import SimLoop
from lowerbase.tasks.model import AUTO_TASK_ID, TaskRequest
from lowerbase.tasks.model import ActionType as AT
from lowerbase.tasks.model import RobotState as RS
from lowerbase.tasks.model import TaskState as TS
from lowerbase.tasks.plan import TaskConfig
from lowerbase.tasks.sim import TaskSim
from lowerbase.world.sim import WorldConfig, WorldSim

FINAL = (TS.COMPLETED, TS.CANCELLED, TS.FAILED)


def make(soc: float = 80.0, **cfg: float) -> TaskSim:
    world = WorldSim(WorldConfig(map="warehouse", start="start"), loop=SimLoop(soc=soc))
    ts = TaskSim(NavSim(world), config=TaskConfig(**cfg))  # type: ignore[arg-type]
    assert ts.run_until(lambda s: s.status.robot_state in (RS.IDLE, RS.WARNING), 5.0)
    return ts


def test_a_transport_task_across_the_warehouse_ends_on_the_mark() -> None:
    ts = make(load_time=4.0)
    mark = ts.places.storage["B1-01"]
    r = ts.request(TaskRequest(1, 11, 4, direction=1, mark_no="B1-01"))
    assert r.success and r.status_code == RS.TASK
    assert ts.run_until(lambda s: s.status.action_type == AT.TRANSPORT, 120)
    t_load, at_load = ts.now, ts.world.true_pose()
    assert math.dist(at_load[:2], mark[:2]) < 0.1  # the truth, not the estimate
    assert ts.run_until(lambda s: s.status.task_state in FINAL, 10)
    assert ts.status.task_state == TS.COMPLETED and ts.status.robot_state == RS.IDLE
    assert ts.now - t_load == pytest.approx(4.0, abs=0.11)
    after = ts.world.true_pose()
    assert math.dist(after[:2], at_load[:2]) < 0.005  # stood still while loading
    assert ts.world.contact_events == []
    states = [(h.task_state, h.action_type) for h in ts.machine.tracker.history]
    assert states[-3:] == [(TS.EXECUTING, AT.NAVIGATION), (TS.EXECUTING, AT.TRANSPORT),
                           (TS.COMPLETED, AT.TRANSPORT)]


def test_an_estop_through_the_driver_pauses_the_task() -> None:
    ts = make()
    assert ts.request(TaskRequest(1, 3, 2, mark_no="A1-03")).success
    ts.run(8.0)
    driver = ts.world.loop.driver
    driver.control("EStopSet")
    assert ts.run_until(lambda s: s.status.task_state == TS.PAUSED, 1.0)
    assert ts.status.robot_state == RS.ABNORMAL
    ts.run(2.0)
    held = ts.world.true_pose()
    ts.run(3.0)
    assert math.dist(ts.world.true_pose()[:2], held[:2]) < 0.005  # the chassis holds
    assert not ts.request(TaskRequest(3, 3)).success  # e-stop still on
    driver.control("EStopRelease")
    driver.control("EnableCanControl")
    ts.run(1.0)
    assert ts.status.task_state == TS.PAUSED  # released: continuing is the operator's call
    assert ts.request(TaskRequest(3, 3)).success
    assert ts.run_until(lambda s: s.status.task_state in FINAL, 120)
    assert ts.status.task_state == TS.COMPLETED
    mark = ts.places.storage["A1-03"]
    assert math.dist(ts.world.true_pose()[:2], mark[:2]) < 0.1


def test_low_battery_sends_the_robot_to_charge_and_the_bms_charges() -> None:
    ts = make(soc=19.9, full_soc=19.9)
    assert ts.status.robot_state == RS.WARNING  # low battery
    assert ts.run_until(lambda s: s.status.task_id == AUTO_TASK_ID and
                        s.status.task_state == TS.EXECUTING, 2.0)
    assert ts.run_until(lambda s: s.status.action_type == AT.CHARGING or
                        s.status.task_state in FINAL, 120)
    assert ts.status.robot_state == RS.CHARGING, ts.status
    charger = ts.places.charger
    assert charger is not None
    x, y, yaw = ts.world.true_pose()
    assert math.hypot(x - charger.pose[0], y - charger.pose[1]) < 0.05
    assert abs(math.remainder(yaw - charger.pose[2], math.tau)) < math.radians(5)
    ts.run(2.0)  # the next BMS polls
    snap = ts.world.loop.driver.bms.snapshot()
    assert snap is not None and snap.current > 5.0  # CC: the charger's current into the pack
    assert ts.run_until(lambda s: s.status.task_state in FINAL, 400)
    assert ts.status.task_state == TS.COMPLETED, ts.status
    assert ts.world.loop.mcu.bms.device.pack.soc >= 19.9
    x, y, _ = ts.world.true_pose()
    assert math.hypot(x - charger.approach[0], y - charger.approach[1]) < 0.05  # undocked
    assert not ts.charger_closed and ts.status.robot_state in (RS.IDLE, RS.WARNING)
