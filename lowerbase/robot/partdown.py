"""A part of the real-time robot that ended, told on robot_status before anything stops (issue
22 item 8): the supervisor writes the crash into the master's ``/lowerbase/part_down``; the
tasks node (lowerbase/tasks/inputs.py) shows it on robot_status (ABNORMAL, the running task
failed) and on /rosout, and acknowledges it in ``/lowerbase/part_reported``. The supervisor
waits for that acknowledgement (at most :data:`REPORT_WAIT`) before it stops the others, so a
customer's task software sees why its robot stopped. A respawned part clears the note."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

from lowerbase.errors import LowerbaseError
from lowerbase.robot.master import delete_param, get_param, set_param
from lowerbase.robot.supervisor import Child
from lowerbase.tasks.inputs import PART_DOWN_PARAM, PART_NOTE_MAX, PART_REPORTED_PARAM
from lowerbase.text import clip

REPORT_WAIT = 3.0  #: [s] at most, for robot_status to carry a crash before the robot stops
POLL = 0.05  #: [s] between looks at the acknowledgement


def part_note(child: Child) -> str:
    """``"<part> ended (exit code N): <its last lines>"``: what robot_status says."""
    last = " | ".join(child.final_lines or child.tail(3)) or child.last_line or "no output"
    return clip(f"{child.spec.name} ended (exit code {child.poll()}): {last}", PART_NOTE_MAX)


class PartReport:
    """The supervisor's side, on the master at ``uri``."""

    def __init__(self, uri: str, *, wait: float = REPORT_WAIT,
                 monotonic: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.uri, self.wait = uri, wait
        self._monotonic, self._sleep = monotonic, sleep
        self.reported: list[str] = []  #: the notes robot_status carried, in order

    def clear(self) -> None:
        """No part down (a run's start: nothing left from an earlier run on this master)."""
        set_param(self.uri, PART_DOWN_PARAM, "")
        set_param(self.uri, PART_REPORTED_PARAM, "")

    def down(self, child: Child, reporter_alive: Callable[[], bool]) -> bool:
        """Tell that ``child`` ended; True once robot_status carries it (False: no tasks
        node to tell it, or none within ``wait``)."""
        note = part_note(child)
        set_param(self.uri, PART_DOWN_PARAM, note)
        deadline = self._monotonic() + self.wait
        while reporter_alive():
            if get_param(self.uri, PART_REPORTED_PARAM) == note:
                self.reported.append(note)
                return True
            if self._monotonic() >= deadline:
                break
            self._sleep(POLL)
        return False

    def up(self) -> None:
        """The part is running again (respawned)."""
        set_param(self.uri, PART_DOWN_PARAM, "")

    def close(self) -> None:
        for name in (PART_DOWN_PARAM, PART_REPORTED_PARAM):
            with contextlib.suppress(OSError, LowerbaseError):
                delete_param(self.uri, name)
