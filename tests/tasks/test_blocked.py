"""The path-blocked warning is debounced (docs/tasks.md, "Chassis events", path blocked): the
navigation must report its path blocked continuously for ``blocked_delay`` s (simulated clock)
before the action warns; it clears on the first free tick. A cell that flickers between scans
gives no WARNING and no robot_status at all."""

from __future__ import annotations

import pytest

from lowerbase.errors import LowerbaseError
from lowerbase.tasks.model import ActionState as AS
from lowerbase.tasks.model import RobotState as RS
from lowerbase.tasks.model import Status
from lowerbase.tasks.plan import TaskConfig
from tests.tasks.bench import Bench
from tests.tasks.test_events import moving
from tests.tasks.test_machine import CONT, PAUSE, ready


def block(b: Bench, on: bool) -> None:
    b.nav.force = "ACTIVE" if on else None
    b.nav.status = "BLOCKED" if on else ""
    b.nav.reason = "waiting: an obstacle blocks the path" if on else ""


def watch(b: Bench) -> list[tuple[float, Status]]:
    """(the machine's time, status) of every robot_status published from now on."""
    out: list[tuple[float, Status]] = []
    b.machine.tracker.publish = lambda s: out.append((b.machine.now, s))
    return out


def test_a_flickering_block_gives_no_warning_and_no_robot_status() -> None:
    b = moving(ready())
    published = watch(b)
    for i in range(80):  # 4 s: blocked / free every 50 ms (one tick each)
        block(b, i % 2 == 0)
        b.tick()
        assert b.status.action_state == AS.EXECUTING and b.status.robot_state == RS.PARKING
    assert published == []


def test_a_block_shorter_than_the_delay_is_not_reported() -> None:
    b = moving(ready())
    published = watch(b)
    for _ in range(5):  # blocked 0.45 s, free one tick: the wait starts again each time
        block(b, True)
        b.tick(9)
        block(b, False)
        b.tick()
    assert published == []


def test_blocked_for_one_second_warns_once_after_the_delay() -> None:
    b = moving(ready())
    published = watch(b)
    start = b.now
    block(b, True)
    b.tick(20)  # 1 s
    block(b, False)
    b.tick()
    assert [(s.action_state, s.robot_state) for _, s in published] == [
        (AS.WARNING, RS.WARNING), (AS.EXECUTING, RS.PARKING)]
    (warned, s), (cleared, _) = published
    assert s.msg == "path blocked: waiting: an obstacle blocks the path"
    assert warned == pytest.approx(start + 0.5)  # the first tick blocked for 0.5 s
    assert cleared == pytest.approx(start + 1.0)  # the first free tick


def test_the_delay_is_configurable_and_zero_warns_at_once() -> None:
    for delay, ticks in ((0.0, 0), (1.0, 20)):
        b = Bench(TaskConfig(blocked_delay=delay))
        b.tick()
        moving(b)
        block(b, True)
        b.tick(ticks)
        assert b.status.action_state == AS.EXECUTING
        b.tick()
        assert b.status.action_state == AS.WARNING and b.status.robot_state == RS.WARNING


def test_the_wait_starts_again_after_a_pause() -> None:
    b = moving(ready())
    block(b, True)
    b.tick(8)
    assert b.send(PAUSE, 1).success
    b.tick(20)
    assert b.send(CONT, 1).success
    b.tick(8)  # 0.4 s blocked since the goal was sent again
    assert b.status.action_state == AS.EXECUTING
    b.tick(3)
    assert b.status.action_state == AS.WARNING


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf")])
def test_a_bad_blocked_delay_is_refused_in_one_line(bad: float) -> None:
    with pytest.raises(LowerbaseError, match=r"^task config blocked_delay must be a number "
                                             r">= 0, got .*$"):
        TaskConfig(blocked_delay=bad)
