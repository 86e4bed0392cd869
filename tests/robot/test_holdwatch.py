"""lowerbase.robot.holdwatch on made-up clocks: a lockstep robot held by a subscriber that reads
no more is warned of, with who holds it, at most once per warn_every; a paused robot, or one
whose time moves, is not."""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence

import pytest

from lowerbase.robot.holdwatch import HoldWatch

HOLDER = "/scan -> /slow (2048 KiB unsent)"


class Rig:
    def __init__(self, holders: Sequence[str] = (HOLDER,)) -> None:
        self.wall, self.sim, self.running = 0.0, 0.0, True
        self.holders = list(holders)
        self.watch = HoldWatch(lambda: self.sim, lambda: self.running, lambda: self.holders,
                               warn_after=5.0, warn_every=30.0, wall=lambda: self.wall)

    def look(self, wall: float, sim: float | None = None) -> str | None:
        self.wall = wall
        if sim is not None:
            self.sim = sim
        return self.watch.look()


def test_a_held_robot_is_warned_of_with_its_holders(caplog: pytest.LogCaptureFixture) -> None:
    rig = Rig()
    assert rig.look(0.0, 1.0) is None
    assert rig.look(4.9) is None  # held 4.9 s: not yet
    with caplog.at_level(logging.WARNING, logger="lowerbase.robot"):
        said = rig.look(5.0)
    assert said is not None and said.startswith("simulated time held at 1.000 s for 5 s")
    assert HOLDER in said and "it goes on when they read again" in said
    assert said in caplog.text
    assert rig.look(20.0) is None  # once per warn_every
    assert rig.look(35.0) is not None
    assert rig.watch.stats["holds_warned"] == 2
    assert rig.look(36.0, 1.05) is None and rig.look(40.0) is None  # it moved: anew


def test_a_paused_or_moving_robot_is_no_hold() -> None:
    rig = Rig()
    rig.running = False  # paused, no step asked for: time stands by design
    assert [rig.look(t, 2.0) for t in (0.0, 10.0, 100.0)] == [None] * 3
    rig.running = True
    assert [rig.look(100.0 + t, 2.0 + t) for t in range(20)] == [None] * 20
    assert rig.watch.stats["holds_warned"] == 0


def test_a_hold_without_holders_says_the_step_is_slow() -> None:
    rig = Rig(holders=())
    rig.look(0.0, 3.0)
    said = rig.look(6.0)
    assert said is not None and "no subscriber holds it" in said


def test_the_watch_thread_looks_and_stops() -> None:
    looked = threading.Event()
    watch = HoldWatch(lambda: 0.0, lambda: looked.set() or True, lambda: [], period=0.01)
    watch.start()
    assert looked.wait(60.0)
    watch.close()
    assert watch._thread is not None and not watch._thread.is_alive()
