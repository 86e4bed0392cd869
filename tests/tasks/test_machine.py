"""The task state machine, row by row of docs/tasks.md, on a fake navigation and chassis."""

from __future__ import annotations

import math

import pytest

from lowerbase.tasks.model import ActionState as AS
from lowerbase.tasks.model import ActionType as AT
from lowerbase.tasks.model import RobotState as RS
from lowerbase.tasks.model import TaskState as TS
from lowerbase.tasks.plan import TaskConfig
from tests.tasks.bench import PLACES, Bench

EXEC, PAUSE, CONT, CANCEL, WAIT = 1, 2, 3, 4, 6
PICK, PARK, CHARGE, TRANSPORT = 1, 2, 3, 4


def ready() -> Bench:
    b = Bench()
    b.tick()
    assert b.status.robot_state == RS.IDLE
    return b


def done(b: Bench) -> bool:
    return b.status.task_state in (TS.COMPLETED, TS.CANCELLED, TS.FAILED)


def seq(b: Bench, field: str) -> list[int]:
    """The distinct successive values of a robot_status field as published."""
    out: list[int] = []
    for s in b.machine.tracker.history:
        v = getattr(s, field)
        if not out or out[-1] != v:
            out.append(v)
    return out


# -- transitions ------------------------------------------------------------------------------
def test_parking_drives_to_the_mark_and_completes() -> None:
    b = ready()
    r = b.send(EXEC, 7, PARK, mark_no="S2")
    assert r.success and r.status_code == RS.PARKING
    assert b.status.task_state == TS.EXECUTING and b.status.action_type == AT.NAVIGATION
    assert b.status.dest == "S2" and b.nav.goals[-1][0] == PLACES.storage["S2"]
    assert b.until(lambda: done(b))
    assert b.status.task_state == TS.COMPLETED and b.status.robot_state == RS.IDLE
    assert math.dist(b.pose[:2], PLACES.storage["S2"][:2]) < 0.01
    assert seq(b, "robot_state") == [RS.UNINITIALIZED, RS.IDLE, RS.PARKING, RS.IDLE]


@pytest.mark.parametrize("task_type,direction,seconds", [
    (TRANSPORT, 1, 3.0), (PICK, 2, 2.0), (TRANSPORT, 0, 0.0), (PICK, 0, 0.0)])
def test_transport_and_picking_load_or_unload_for_the_configured_time(
        task_type: int, direction: int, seconds: float) -> None:
    b = ready()
    assert b.send(EXEC, 3, task_type, direction=direction, mark_no="S1").success
    assert b.status.robot_state == RS.TASK
    assert b.until(lambda: b.status.action_type != AT.NAVIGATION or done(b))
    start = b.now
    assert b.until(lambda: done(b))
    assert b.status.task_state == TS.COMPLETED
    if seconds:
        assert seq(b, "action_type") == [AT.UNDEFINED, AT.NAVIGATION, AT.TRANSPORT]
        assert b.now - start == pytest.approx(seconds, abs=0.051)
        assert all(t is None for t in b.twists[-int(seconds / 0.05):])  # standing still
    else:
        assert AT.TRANSPORT not in seq(b, "action_type")


def test_charging_docks_charges_undocks_when_full() -> None:
    b = ready()
    b.soc = 97.0
    assert b.send(EXEC, 5, CHARGE).success
    assert b.nav.goals[-1][0] == PLACES.charger.approach  # type: ignore[union-attr]
    assert b.until(lambda: b.status.action_type == AT.CHARGING)
    assert b.status.robot_state == RS.CHARGING
    assert math.dist(b.pose[:2], PLACES.charger.pose[:2]) < 0.01  # type: ignore[union-attr]
    assert b.until(lambda: done(b))
    assert b.status.task_state == TS.COMPLETED and b.soc >= 100.0
    assert seq(b, "action_type") == [AT.UNDEFINED, AT.NAVIGATION, AT.DOCK_IN, AT.CHARGING,
                                     AT.DOCK_OUT]
    assert math.dist(b.pose[:2], PLACES.charger.approach[:2]) < 0.01  # type: ignore
    assert b.status.robot_state == RS.IDLE and not b.machine.docked


def dock(b: Bench, tid: int = 5) -> None:
    assert b.send(EXEC, tid, CHARGE).success
    assert b.until(lambda: b.status.action_type == AT.CHARGING)


def test_a_new_task_ends_charging_and_undocks_first() -> None:
    b = ready()
    dock(b)
    r = b.send(EXEC, 6, PARK, mark_no="S1")
    assert r.success
    hist = list(b.machine.tracker.history)
    assert (hist[-2].task_id, hist[-2].task_state) == (5, TS.COMPLETED)
    assert "charging ended" in hist[-2].msg
    assert (b.status.task_id, b.status.action_type) == (6, AT.DOCK_OUT)
    assert b.until(lambda: done(b))
    assert seq(b, "action_type")[-2:] == [AT.DOCK_OUT, AT.NAVIGATION]
    assert b.status.task_state == TS.COMPLETED and math.dist(b.pose[:2], (4.0, 0.0)) < 0.01


def test_cancel_while_charging_stays_docked_and_charging() -> None:
    b = ready()
    dock(b)
    assert b.send(CANCEL, 5).success
    b.tick(20)
    assert b.status.task_state == TS.CANCELLED and b.status.robot_state == RS.CHARGING
    assert b.machine.docked and b.on_charger()
    assert b.send(EXEC, 6, CHARGE).success  # charging again: no navigation, no docking
    assert b.status.action_type == AT.CHARGING


@pytest.mark.parametrize("corrections", [0, 2])
def test_docking_corrects_an_overshoot_by_the_localized_pose(corrections: int) -> None:
    # odometry reports 90 % of the travel (a driver losing wheel samples: over ROS at
    # --sim-time x2 the 1 m dock-in ended ~10 cm past the charger): the moves end off it
    b = Bench(TaskConfig(dock_timeout=1.0, dock_corrections=corrections))
    b.tick()
    b.odom_scale = 0.9
    assert b.send(EXEC, 5, CHARGE).success
    assert b.until(lambda: b.status.action_type == AT.CHARGING or done(b))
    charger = PLACES.charger
    assert charger is not None
    if corrections == 0:  # as before: the robot stands past the charger, no contact
        assert b.status.task_state == TS.FAILED and "no charger contact" in b.status.msg
        assert math.dist(b.pose[:2], charger.pose[:2]) > 0.05
        return
    # the localized pose is past the charger: a move back along the heading puts it on
    assert b.status.robot_state == RS.CHARGING
    assert math.dist(b.pose[:2], charger.pose[:2]) < 0.02
    assert abs(math.remainder(b.pose[2] - charger.pose[2], math.tau)) < math.radians(2.0)
    assert b.machine.task is not None and 1 <= b.machine.task.dock_corrections <= 2


def test_dock_correction_moves_along_the_heading_without_turning_to_the_charger() -> None:
    from lowerbase.navigation.steps import ROTATE, STRAIGHT
    from lowerbase.tasks.plan import dock_correction

    # 10 cm past a charger facing -x (into a wall), 4 cm beside it, 2 deg off: back 10 cm
    # along the heading, turn 2 deg; no turn towards the charger (it would sweep the wall)
    pose = (0.9, 4.04, math.pi + math.radians(2.0))
    moves = dock_correction(pose, (1.0, 4.0, math.pi))
    assert [m for m, _ in moves] == [STRAIGHT, ROTATE]
    assert moves[0][1] == pytest.approx(-0.0985, abs=0.002)
    assert moves[1][1] == pytest.approx(math.radians(-2.0))
    assert dock_correction((1.0, 4.0, math.pi), (1.0, 4.0, math.pi)) == []


def test_docking_moves_held_by_a_wall_are_stopped_and_corrected() -> None:
    # odometry reports 85 % of the travel, so the 1 m dock drive goes on past the charger into
    # the wall 8 cm behind it, which holds the robot: /odom never arrives. StepControl's stall
    # check ends the list (-3, no progress for 4 s), or at the latest the machine stops the
    # moves after dock_move_timeout; it corrects from the localized pose
    b = Bench(TaskConfig(dock_timeout=1.0, dock_move_timeout=30.0))
    b.tick()
    b.odom_scale, b.wall_y = 0.85, -2.08
    assert b.send(EXEC, 5, CHARGE).success
    assert b.until(lambda: b.status.action_type == AT.CHARGING or done(b), timeout=120.0)
    assert b.status.robot_state == RS.CHARGING
    charger = PLACES.charger
    assert charger is not None and math.dist(b.pose[:2], charger.pose[:2]) < 0.02


def test_a_dock_in_ending_short_far_from_the_charger_is_planned_again_in_full() -> None:
    from lowerbase.navigation.steps import FAILED, ROTATE, STRAIGHT, StepResult

    b = ready()
    assert b.send(EXEC, 5, CHARGE).success
    assert b.until(lambda: b.status.action_type == AT.DOCK_IN)
    # the first turn of the dock-in failed (StepControl: "still 1.0 deg off"), the robot still
    # at the approach pose, 3 deg off: face the charger again, not just drive along the heading
    b.pose = b.odom = (b.pose[0], b.pose[1], b.pose[2] + math.radians(3.0))
    b.machine.steps.result = StepResult(FAILED, 2, 0.0, "step 1: still 1.0 deg off after 5 "
                                        "corrections")
    b.tick()
    steps = b.machine.steps.steps
    assert [s.execute_mode for s in steps][:2] == [ROTATE, STRAIGHT], steps
    assert b.until(lambda: b.status.action_type == AT.CHARGING or done(b))
    assert b.status.robot_state == RS.CHARGING


@pytest.mark.parametrize("contact", [False, True])
def test_a_dock_out_ending_short_goes_on_once_off_the_charger(contact: bool) -> None:
    from lowerbase.navigation.steps import FAILED, StepResult

    b = ready()
    dock(b)
    assert b.send(EXEC, 6, PARK, mark_no="S1").success
    assert b.status.action_type == AT.DOCK_OUT
    # 2 s of the 1 m dock out at 0.1 m/s: off the charger; or one tick: still on it
    b.tick(1 if contact else 40)
    assert b.on_charger() == contact
    # what StepControl answers when /odom disagrees with itself (a driver losing samples)
    b.machine.steps.result = StepResult(FAILED, 1, 20.0,
                                        "step 1: still 15.9 mm off after 5 corrections")
    b.tick()
    if not contact:  # as over ROS: the robot is off the charger, navigation takes it on
        assert (b.status.task_state, b.status.action_type) == (TS.EXECUTING, AT.NAVIGATION)
        assert b.until(lambda: done(b)) and b.status.task_state == TS.COMPLETED
        assert math.dist(b.pose[:2], (4.0, 0.0)) < 0.01
    else:  # still charging: the task fails as before
        assert b.status.task_state == TS.FAILED and "still 15.9 mm off" in b.status.msg


def test_no_charger_contact_after_docking_fails() -> None:
    b = ready()
    b.charger_works = False
    assert b.send(EXEC, 5, CHARGE).success
    assert b.until(lambda: done(b))
    assert b.status.task_state == TS.FAILED and "no charger contact" in b.status.msg


def test_charger_contact_opening_while_charging_fails() -> None:
    b = ready()
    dock(b)
    b.charger_works = False
    b.tick(2)
    assert b.status.task_state == TS.FAILED and "contact opened" in b.status.msg


# -- requests ---------------------------------------------------------------------------------
def test_pause_and_continue_during_navigation() -> None:
    b = ready()
    assert b.send(EXEC, 1, PARK, mark_no="S1").success
    b.tick(10)
    r = b.send(PAUSE, 1)
    assert r.success and b.status.task_state == TS.PAUSED
    assert b.status.action_state == AS.PAUSED and len(b.nav.cancels) == 1
    before = b.pose
    b.tick(20)
    assert b.pose == before and b.twists[-1] == (0.0, 0.0)
    assert b.send(CONT, 1).success and b.status.task_state == TS.EXECUTING
    assert len(b.nav.goals) == 2 and b.nav.goals[-1][0] == PLACES.storage["S1"]
    assert b.until(lambda: done(b)) and b.status.task_state == TS.COMPLETED


def test_wait_for_interruption_and_continue() -> None:
    b = ready()
    assert b.send(EXEC, 1, TRANSPORT, mark_no="S1").success
    b.tick(5)
    r = b.send(WAIT, 1)
    assert r.success and b.status.task_state == TS.WAITING
    assert (b.status.action_type, b.status.wait_id) == (AT.WAITING, 1)
    assert not b.send(PAUSE, 1).success and not b.send(WAIT, 1).success
    assert b.send(CONT, 1).success and b.status.action_type == AT.NAVIGATION
    assert b.until(lambda: done(b)) and b.status.task_state == TS.COMPLETED


@pytest.mark.parametrize("setup,exect,tid,why", [
    ("idle", PAUSE, 1, "no task is running"),
    ("idle", CONT, 1, "no task is running"),
    ("idle", CANCEL, 1, "no task is running"),
    ("idle", WAIT, 1, "no task is running"),
    ("idle", 5, 1, "unknown task_exect 5"),
    ("nav", PAUSE, 2, "task 2 is not the running task"),
    ("nav", CONT, 1, "is not paused"),
    ("paused", PAUSE, 1, "paused already"),
    ("paused", WAIT, 1, "paused already"),
    ("charging", PAUSE, 1, "cannot be paused"),
    ("charging", WAIT, 1, "cannot be paused"),
    ("nav", EXEC, 1, "already running"),
    ("nav", EXEC, 2, "cancel it (4) first"),
    ("paused", EXEC, 2, "cancel it (4) first"),
])
def test_refused_requests_by_state(setup: str, exect: int, tid: int, why: str) -> None:
    b = ready()
    if setup in ("nav", "paused"):
        assert b.send(EXEC, 1, PARK, mark_no="S1").success
        b.tick(3)
    if setup == "paused":
        assert b.send(PAUSE, 1).success
    if setup == "charging":
        dock(b, 1)
    before = b.status
    r = b.send(exect, tid, PARK, mark_no="S2")
    assert not r.success and why in r.message, r.message
    assert r.status_code == b.status.robot_state
    assert b.status == before  # nothing changed


@pytest.mark.parametrize("kw,why", [
    (dict(task_type=9, mark_no="S1"), "unknown task_type 9"),
    (dict(task_type=PARK, direction=3, mark_no="S1"), "unknown direction 3"),
    (dict(task_type=PARK, direction=1, mark_no="S1"), "send direction 0"),
    (dict(task_type=CHARGE, direction=2), "send direction 0"),
    (dict(task_type=PARK, mark_no="Z9"), "unknown mark_no 'Z9'"),
    (dict(task_type=PARK), "no target"),
    (dict(task_type=PARK, mark_no="S1", poses=((1.0, 0.0, 0.0), (4.0, 0.1, 0.0))),
     "is not S1 at"),
    (dict(task_type=PARK, mark_no="S1", poses=((4.0, 0.0, 0.3),)), "is not S1 at"),
    (dict(task_type=PARK, poses=((4.0, math.nan, 0.0),)), "finite"),
    (dict(task_type=CHARGE, mark_no="S1"), "goes to the charger"),
    (dict(task_type=CHARGE, poses=((0.0, -2.0, 0.0),)), "is not charger at"),
    (dict(task_type=PARK, poses=((99.0, 0.0, 0.0),)), "navigation refused the goal"),
])
def test_refused_execute_requests(kw: dict, why: str) -> None:
    b = ready()
    r = b.send(EXEC, 4, **kw)
    assert not r.success and why in r.message, r.message
    assert b.status.task_id == 0 and not b.nav.goals


def test_task_id_must_be_positive_and_the_map_must_have_a_charger() -> None:
    b = ready()
    assert "task_id must be > 0" in b.send(EXEC, 0, PARK, mark_no="S1").message
    assert "task_id must be > 0" in b.send(EXEC, -3, PARK, mark_no="S1").message
    nb = Bench(places=type(PLACES)(storage=dict(PLACES.storage)))
    nb.tick()
    assert "no charger" in nb.send(EXEC, 1, CHARGE).message


def test_poses_ending_on_the_mark_are_the_path() -> None:
    b = ready()
    path = ((2.0, 0.0, 0.0), (4.0, 0.004, 0.005))
    assert b.send(EXEC, 4, PARK, mark_no="S1", poses=path).success
    assert b.nav.goals[-1][:2] == (PLACES.storage["S1"], path)
    b2 = ready()
    assert b2.send(EXEC, 4, PARK, poses=((1.0, 1.0, 0.0),)).success  # a target alone
    assert b2.status.dest.startswith("(1.000, 1.000")


def test_cancel_stops_a_running_task() -> None:
    b = ready()
    assert b.send(EXEC, 1, PARK, mark_no="S1").success
    b.tick(5)
    r = b.send(CANCEL, 1)
    assert r.success and b.status.task_state == TS.CANCELLED
    assert b.status.action_state == AS.CANCELLED and b.nav.cancels
    assert b.status.robot_state == RS.IDLE
    assert b.send(EXEC, 2, PARK, mark_no="S2").success  # free for a new task


@pytest.mark.parametrize("chassis,code,why", [
    (dict(initialized=False), RS.UNINITIALIZED, "not initialized"),
    (dict(e_stopped=True), RS.ABNORMAL, "emergency stop"),
    (dict(fault="left motor fault"), RS.ABNORMAL, "left motor fault"),
    (dict(link_lost=True), RS.ABNORMAL, "link is lost"),
    (dict(part_down="navigation ended (exit code -9): no output"), RS.ABNORMAL,
     "navigation ended (exit code -9)"),
    (dict(initialized=False, part_down="driver ended (exit code 1): boom"), RS.ABNORMAL,
     "driver ended"),
    (dict(critical_battery=True, low_battery=True, soc=3.0), RS.ABNORMAL,
     "battery is critical (3 %)"),
])
def test_execute_refused_by_the_chassis(chassis: dict, code: RS, why: str) -> None:
    b = Bench()
    b.set(**chassis)
    b.machine.config = type(b.machine.config)(auto_charge=False)
    b.tick()
    r = b.send(EXEC, 1, PARK, mark_no="S1")
    assert not r.success and why in r.message and r.status_code == code, r


def test_critical_battery_still_accepts_charging() -> None:
    b = Bench()
    b.set(critical_battery=True, low_battery=True, soc=3.0)
    b.machine.config = type(b.machine.config)(auto_charge=False)
    b.tick()
    assert b.send(EXEC, 1, CHARGE).success


def test_a_huge_mark_no_or_pose_is_quoted_short_in_the_answer_and_the_log(
        caplog: pytest.LogCaptureFixture) -> None:
    """A 1 MB mark_no is refused quoting its first 64 characters and its length, in the
    response and in the log; a pose at 1e300 is quoted as %g."""
    b = ready()
    huge = "Z" * (1 << 20)
    with caplog.at_level("INFO", logger="lowerbase.tasks"):
        for kw in (dict(task_type=PARK, mark_no=huge), dict(task_type=CHARGE, mark_no=huge)):
            r = b.send(EXEC, 4, **kw)  # type: ignore[arg-type]
            assert not r.success and f"'{'Z' * 64}'... (1048576 chars)" in r.message
            assert len(r.message) < 300, len(r.message)
        r = b.send(EXEC, 4, PARK, mark_no="S1", poses=((1e300, 0.0, 0.0),))
        assert not r.success and "(1e+300, 0.000, 0.000)" in r.message, r.message
        assert len(r.message) < 300
    assert caplog.records and max(len(rec.getMessage()) for rec in caplog.records) < 300
