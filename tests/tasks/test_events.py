"""What the chassis does to a task (docs/tasks.md, "Chassis events"), row by row."""

from __future__ import annotations

import itertools
import math

from lowerbase.tasks.model import AUTO_TASK_ID
from lowerbase.tasks.model import ActionState as AS
from lowerbase.tasks.model import ActionType as AT
from lowerbase.tasks.model import RobotState as RS
from lowerbase.tasks.model import TaskState as TS
from tests.tasks.bench import PLACES, Bench
from tests.tasks.test_machine import CANCEL, CHARGE, CONT, EXEC, PARK, TRANSPORT, done, ready, seq


def moving(b: Bench, tid: int = 1, **kw: object) -> Bench:
    assert b.send(EXEC, tid, kw.pop("task_type", PARK), mark_no="S1", **kw).success  # type: ignore[arg-type]
    b.tick(10)
    assert b.status.action_type == AT.NAVIGATION
    return b


def test_estop_pauses_the_task_until_released_and_continued() -> None:
    b = moving(ready())
    b.set(e_stopped=True)
    b.tick()
    s = b.status
    assert (s.task_state, s.action_state, s.robot_state) == (TS.PAUSED, AS.PAUSED, RS.ABNORMAL)
    assert "emergency stop" in s.msg and b.nav.cancels
    r = b.send(CONT, 1)
    assert not r.success and "emergency stop" in r.message and r.status_code == RS.ABNORMAL
    b.set(e_stopped=False)
    b.tick(20)
    assert b.status.task_state == TS.PAUSED and b.status.robot_state == RS.PARKING  # stays
    assert "released: continue (3)" in b.status.msg
    assert b.send(CONT, 1).success
    assert b.until(lambda: done(b)) and b.status.task_state == TS.COMPLETED


def test_estop_during_docking_pauses_the_step_moves() -> None:
    b = ready()
    assert b.send(EXEC, 5, CHARGE).success
    assert b.until(lambda: b.status.action_type == AT.DOCK_IN)
    b.tick(10)
    b.set(e_stopped=True)
    b.tick(40)
    assert b.status.task_state == TS.PAUSED and abs(b.twists[-1][0]) < 1e-9  # type: ignore
    b.set(e_stopped=False)
    b.tick()
    assert b.send(CONT, 5).success
    assert b.until(lambda: b.status.action_type == AT.CHARGING)
    assert math.dist(b.pose[:2], PLACES.charger.pose[:2]) < 0.01  # type: ignore[union-attr]


def test_estop_while_charging_keeps_charging() -> None:
    b = ready()
    assert b.send(EXEC, 5, CHARGE).success
    assert b.until(lambda: b.status.action_type == AT.CHARGING)
    b.set(e_stopped=True)
    b.tick(5)
    assert b.status.task_state == TS.EXECUTING and b.status.robot_state == RS.ABNORMAL


def test_a_fault_fails_the_task() -> None:
    b = moving(ready())
    b.set(fault="left motor fault")
    b.tick()
    s = b.status
    assert (s.task_state, s.action_state, s.robot_state) == (TS.FAILED, AS.FAILED, RS.ABNORMAL)
    assert "left motor fault" in s.msg and b.nav.cancels
    b.set(fault="")
    b.tick()
    assert b.status.robot_state == RS.IDLE
    assert b.send(EXEC, 2, PARK, mark_no="S1").success  # send it again once cleared


def test_link_lost_fails_the_task() -> None:
    b = moving(ready())
    b.set(link_lost=True)
    b.tick()
    assert b.status.task_state == TS.FAILED and "link is lost" in b.status.msg


def test_a_part_that_ended_fails_the_task_and_shows_until_it_is_back() -> None:
    """Issue 22 item 8: a crashed part of the robot (the supervisor's note) is on robot_status
    at once: ABNORMAL, the task failed with the crash's own words; a respawned part clears it."""
    b = moving(ready())
    note = "navigation ended (exit code 1): RuntimeError: navigation broke"
    b.set(part_down=note)
    b.tick()
    s = b.status
    assert (s.task_state, s.action_state, s.robot_state) == (TS.FAILED, AS.FAILED, RS.ABNORMAL)
    assert note in s.msg and b.nav.cancels
    b.set(part_down="")
    b.tick()
    assert b.status.robot_state == RS.IDLE
    assert b.send(EXEC, 2, PARK, mark_no="S1").success


def test_low_battery_warns_finishes_the_task_then_charges() -> None:
    b = moving(ready(), task_type=TRANSPORT, direction=1)
    b.set(low_battery=True, soc=18.0)
    b.tick()
    assert b.status.robot_state == RS.WARNING and b.status.task_state == TS.EXECUTING
    assert b.until(lambda: b.status.task_id == AUTO_TASK_ID, 60)
    assert b.machine.tracker.history[-2].task_state == TS.COMPLETED  # the task finished first
    s = b.status
    assert (s.task_type, s.task_state, s.action_type) == (CHARGE, TS.EXECUTING, AT.NAVIGATION)
    assert "battery low" in s.msg
    assert b.until(lambda: b.status.action_type == AT.CHARGING)
    assert b.status.robot_state == RS.CHARGING


def test_critical_battery_fails_the_task_then_charges() -> None:
    b = moving(ready())
    b.set(low_battery=True, critical_battery=True, soc=4.0)
    b.tick()
    hist = list(b.machine.tracker.history)
    failed = [h for h in hist if h.task_id == 1 and h.task_state == TS.FAILED]
    assert failed and "battery critical (4 %)" in failed[0].msg
    assert b.status.task_id == AUTO_TASK_ID and b.status.task_type == CHARGE
    assert b.status.robot_state == RS.ABNORMAL


def test_auto_charge_once_per_low_battery_episode_and_can_be_off() -> None:
    b = ready()
    b.set(low_battery=True, soc=18.0)
    b.tick()
    assert b.status.task_id == AUTO_TASK_ID
    assert b.send(CANCEL, AUTO_TASK_ID).success
    b.tick(20)
    assert b.status.task_state == TS.CANCELLED  # not started again while still low
    b.set(low_battery=False, soc=30.0)
    b.tick()
    b.set(low_battery=True, soc=19.0)
    b.tick()
    assert b.status.task_state == TS.EXECUTING  # a new episode
    off = Bench()
    off.machine.config = type(off.machine.config)(auto_charge=False)
    off.set(low_battery=True, soc=18.0)
    off.tick(20)
    assert off.status.task_id == 0 and off.status.task_state == 0
    assert off.status.robot_state == RS.WARNING and "battery low (18 %)" in off.status.msg


def test_localization_loss_holds_navigation_until_it_returns() -> None:
    b = moving(ready())
    b.set(localized=False)
    b.tick()
    s = b.status
    assert (s.task_state, s.action_state, s.robot_state) == (TS.EXECUTING, AS.WARNING,
                                                               RS.WARNING)
    assert "localization lost" in s.msg and len(b.nav.cancels) == 1
    before = b.pose
    b.tick(20)
    assert b.pose == before
    b.set(localized=True)
    b.tick()
    assert b.status.action_state == AS.EXECUTING and len(b.nav.goals) == 2
    assert b.until(lambda: done(b)) and b.status.task_state == TS.COMPLETED


def test_blocked_path_warns_and_an_abort_fails() -> None:
    b = moving(ready())
    b.nav.force, b.nav.status, b.nav.reason = "ACTIVE", "blocked", "blocked by an obstacle"
    b.tick(10)  # blocked_delay (0.5 s; tests/tasks/test_blocked.py)
    assert b.status.action_state == AS.EXECUTING
    b.tick()
    s = b.status
    assert (s.action_state, s.robot_state) == (AS.WARNING, RS.WARNING)
    assert "path blocked" in s.msg
    b.nav.force, b.nav.status, b.nav.reason = "ACTIVE", "", ""
    b.tick()
    assert (b.status.action_state, b.status.robot_state) == (AS.EXECUTING, RS.PARKING)
    b.nav.force, b.nav.reason = "ABORTED", "no path to the goal"
    b.tick()
    assert b.status.task_state == TS.FAILED and "no path to the goal" in b.status.msg
    assert b.status.robot_state == RS.IDLE


def test_robot_status_is_published_only_on_change() -> None:
    b = ready()
    published: list[object] = []
    b.machine.tracker.publish = published.append
    b.tick(50)
    assert published == []
    assert b.send(EXEC, 1, PARK, mark_no="S1").success
    assert b.until(lambda: done(b))
    hist = list(b.machine.tracker.history)
    assert all(a != c for a, c in itertools.pairwise(hist))
    assert published == hist[-len(published):] and len(published) == 2  # executing, completed
    assert seq(b, "task_state") == [0, TS.EXECUTING, TS.COMPLETED]
    assert published[-1].time == int(b.machine.now)  # type: ignore[attr-defined]


def test_battery_bits_without_a_bms_reading_yet() -> None:
    b = Bench()
    b.machine.config = type(b.machine.config)(auto_charge=False)
    b.set(low_battery=True, soc=None)
    b.soc = None  # type: ignore[assignment]
    b.ch = b.ch.__class__(**{**b.ch.__dict__, "soc": None})
    b.machine.tick(0.0, b.ch)
    assert b.status.robot_state == RS.WARNING and b.status.msg == "battery low"


def test_auto_charge_waits_for_the_chassis_to_come_up() -> None:
    b = Bench()
    b.set(initialized=False, low_battery=True, soc=18.0)
    b.tick(10)
    assert b.status.task_id == 0 and b.status.robot_state == RS.UNINITIALIZED
    b.set(initialized=True)
    b.tick()
    assert b.status.task_id == AUTO_TASK_ID and b.status.task_state == TS.EXECUTING
