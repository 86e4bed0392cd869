"""A wall-clock scenario run counts how far the host kept it late (lowerbase.scenarios.lag).

The bus harness runs on a scripted clock and bus: a step held up by the host, and Heartbeats
whose Overruns move, are counted; an on-time run counts nothing.
"""

from __future__ import annotations

from collections import deque

import can
import pytest

from lowerbase.clock import SimClock
from lowerbase.protocol.codec import default_codec
from lowerbase.scenarios.demo import BusHarness
from lowerbase.scenarios.lag import LATE_STEP, HostLag

HEARTBEAT = default_codec().message("Heartbeat")


def heartbeat(uptime: float, overruns: int) -> can.Message:
    data = HEARTBEAT.encode({"Uptime": uptime, "BootCounter": 1, "Counter": 0,
                             "Overruns": overruns, "ProtocolVersion": 1})
    return can.Message(arbitration_id=HEARTBEAT.frame_id, data=data, is_extended_id=False)


class ScriptedBus:
    """recv() waits on the simulated clock; ``stall`` holds the host up once, at a time."""

    def __init__(self, clock: SimClock) -> None:
        self.clock = clock
        self.inbox: deque[can.Message] = deque()
        self.stalls: dict[int, float] = {}  # recv call number -> extra seconds
        self.calls = 0

    def recv(self, timeout: float | None = None) -> can.Message | None:
        self.calls += 1
        self.clock.advance(self.stalls.pop(self.calls, 0.0))
        if self.inbox:
            return self.inbox.popleft()
        self.clock.advance(max(timeout or 0.0, 0.0))
        return None

    def send(self, msg: can.Message) -> None:
        pass


def harness() -> tuple[BusHarness, ScriptedBus]:
    clock = SimClock(100.0)
    bus = ScriptedBus(clock)
    h = BusHarness(bus, clock=clock)
    bus.inbox.append(heartbeat(0.2, 0))
    h.start()
    return h, bus


def test_an_on_time_run_counts_nothing() -> None:
    h, _ = harness()
    for _ in range(400):
        h.step()
    assert h.lag == HostLag() and not h.lag.lagged


def test_a_step_the_host_held_up_is_counted_late() -> None:
    h, bus = harness()
    stall = 0.3 + h.dt / 2
    bus.stalls[bus.calls + 50] = stall  # the 50th wait comes back 0.3 s late
    bus.stalls[bus.calls + 150] = LATE_STEP / 2  # a small slip is not late
    for _ in range(300):
        h.step()
    assert h.lag is not None
    # the steps due while the host held the run up start late, catching up one by one,
    # until the run is less than LATE_STEP behind
    caught_up_while_late = int((stall - LATE_STEP) / h.dt) + 1
    assert h.lag.late_steps == caught_up_while_late == 51
    assert h.lag.max_late == pytest.approx(stall)
    assert "51 steps started late (worst 0.30 s)" in h.lag.describe()


def test_a_long_stall_is_counted_and_not_caught_up_in_a_burst() -> None:
    h, bus = harness()
    bus.stalls[bus.calls + 10] = 2.5
    for _ in range(100):
        h.step()
    assert h.lag is not None and h.lag.late_steps == 1
    assert h.lag.max_late == pytest.approx(2.5)


def test_the_lower_computers_overruns_are_counted_modulo_16() -> None:
    h, bus = harness()
    for uptime, overruns in ((0.7, 0), (1.2, 3), (1.7, 14), (2.2, 1)):
        bus.inbox.append(heartbeat(uptime, overruns))
        for _ in range(100):
            h.step()
    assert h.lag is not None and h.lag.lower_overruns == 3 + 11 + 3
    assert h.lag.late_steps == 0
    assert "the lower computer counted 17 Overruns" in h.lag.describe()
    assert h.lag.as_dict()["lagged"] is True
