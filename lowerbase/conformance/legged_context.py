"""What every legged check gets: the link to the four leg buses, the settings, the catalog
(``legged.dbc``), and helpers to read LocomotionStatus and to drive the state machine."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from lowerbase.conformance.core import Check, CheckSkipped, Outcome, require
from lowerbase.conformance.legged_link import LegFrame, LeggedLink
from lowerbase.errors import ProtocolError
from lowerbase.protocol.codec import MessageCodec, Signals
from lowerbase.protocol.legged import (
    BODY_BUS,
    COMMAND_MESSAGES,
    REPLY_ID,
    LocomotionState,
    legged_codec,
)

S = LocomotionState
#: [s] a LocomotionStatus received this long after a request reflects it (frames in flight)
SETTLE = 0.03
POLL = 0.005  #: [s] how often waits look at what arrived


@dataclass(frozen=True)
class LeggedSettings:
    """Tolerances and bounds of a legged run (docs/conformance.md, *Legged robot*)."""

    observe: float = 3.5  #: [s] the frame checks' window (>= 3 cycles of the Bms* frames)
    cycle_tolerance: float = 0.10  #: mean interval within +-10 % of the catalog cycle
    max_gap_cycles: float = 2.5  #: no gap above this many cycles ...
    jitter: float = 0.05  #: [s] ... plus this allowance for the receiving host
    link_timeout: float = 3.0  #: [s] to hear the lower computer at all
    reply_timeout: float = 1.0  #: [s] for an answer or a state change
    transition_timeout: float = 5.0  #: [s] commutation, standing up, sitting down
    speed: float = 0.2  #: [m/s] the BodyVelocityCommand the suite walks with
    command_timeout: float = 0.5  #: [s] the body controller's BodyVelocityCommand timeout
    motion: bool = True  #: False skips standing up and walking
    zero_position: bool = False  #: also send the zero-position frame (re-zeroes FR hip)


LeggedCheckFunc = Callable[["LeggedContext"], Outcome]


def legged_check(check_id: str, description: str, func: LeggedCheckFunc) -> Check:
    """A :class:`Check` whose function takes a :class:`LeggedContext` (the runner passes one;
    the shared Check/Report/JUnit types are the wheeled suite's)."""
    return Check(check_id, description, func)


class LeggedContext:
    """The link, the settings and state shared between the checks of one run."""

    def __init__(self, link: LeggedLink, settings: LeggedSettings) -> None:
        self.link = link
        self.settings = settings
        self.codec = legged_codec()
        self.linked = False
        self.shared: dict[str, Any] = {}
        self._request_counter = 0
        self._status = self.codec.message("LocomotionStatus")
        self._request = self.codec.message("LocomotionRequest")
        self.commands = {mid: self.codec.message(n) for mid, n in COMMAND_MESSAGES.items()}
        self.reply = self.codec.message("MotorReply")

    # -- time --------------------------------------------------------------------------------

    def now(self) -> float:
        return self.link.now()

    def wait(self, seconds: float) -> None:
        self.link.wait(seconds)

    def wait_until(self, condition: Callable[[], bool], timeout: float) -> bool:
        deadline = self.now() + timeout
        while True:
            if condition():
                return True
            if self.now() >= deadline:
                return False
            self.wait(POLL)

    @contextmanager
    def capturing(self) -> Iterator[None]:
        """Keep the actuator traffic while inside (forgotten when the outermost ends)."""
        outer = not self.link.capture
        self.link.capture = True
        try:
            yield
        finally:
            if outer:
                self.link.capture = False
                self.link.forget_actuator_traffic()

    # -- body frames ---------------------------------------------------------------------------

    def body_frames(self, msg: MessageCodec, since: float = -math.inf,
                    until: float = math.inf) -> list[LegFrame]:
        return self.link.frames(BODY_BUS, msg.frame_id, since, until)

    def decoded(self, name: str, since: float = -math.inf, until: float = math.inf
                ) -> list[tuple[float, Signals]]:
        """(time, values) of the body frames ``name`` that decode (non-strictly)."""
        msg = self.codec.message(name)
        out = []
        for f in self.body_frames(msg, since, until):
            try:
                out.append((f.t, msg.decode(f.data, strict=False)))
            except ProtocolError:
                continue
        return out

    def status(self, since: float, timeout: float | None = None) -> Signals:
        """The first LocomotionStatus received after ``since`` (waiting for one)."""
        got: list[Signals] = []

        def arrived() -> bool:
            got[:] = [v for _, v in self.decoded("LocomotionStatus", since)]
            return bool(got)

        wait = 2 * (self._status.cycle_time or 0.0) + self.settings.reply_timeout
        require(self.wait_until(arrived, wait if timeout is None else timeout),
                "no LocomotionStatus from the lower computer")
        return got[0]

    def state(self) -> int:
        """The State of the newest LocomotionStatus (at most 1.5 cycles old)."""
        since = self.now() - (self._status.cycle_time or 0.02) * 1.5
        self.status(since)
        return int(self.decoded("LocomotionStatus", since)[-1][1]["State"])

    def wait_state(self, predicate: Callable[[int], bool], timeout: float
                   ) -> tuple[float, Signals] | None:
        """The first LocomotionStatus from now on whose State satisfies ``predicate``."""
        since = self.now()
        found: list[tuple[float, Signals]] = []

        def seen() -> bool:
            found[:] = [(t, v) for t, v in self.decoded("LocomotionStatus", since)
                        if predicate(int(v["State"]))][:1]
            return bool(found)

        return found[0] if self.wait_until(seen, timeout) else None

    # -- requests ------------------------------------------------------------------------------

    def send_request(self, state: int, data: bytes | None = None, bus: int = BODY_BUS) -> float:
        """Send LocomotionRequest ``state`` (or the raw ``data``); returns the send time."""
        if data is None:
            data = self._request.encode({"Request": state, "Counter": self._request_counter})
            self._request_counter = (self._request_counter + 1) % 16
        t = self.now()
        self.link.send(bus, self._request.frame_id, data)
        return t

    def request(self, state: int) -> Signals:
        """Send a request; the first LocomotionStatus that answers it (LastRequest), or
        after ``reply_timeout`` the newest one."""
        t = self.send_request(state)
        first = self.status(t + SETTLE)
        if int(first["LastRequest"]) == state:
            return first
        answers: list[Signals] = []

        def answered() -> bool:
            answers[:] = [v for _, v in self.decoded("LocomotionStatus", t + SETTLE)
                          if int(v["LastRequest"]) == state][:1]
            return bool(answers)

        if self.wait_until(answered, self.settings.reply_timeout):
            return answers[0]
        return self.decoded("LocomotionStatus", t + SETTLE)[-1][1]

    def result_name(self, values: Signals) -> str:
        return self._status.signal("RequestResult").choices.get(int(values["RequestResult"]),
                                                                str(values["RequestResult"]))

    def go_to(self, target: S) -> int:
        """Walk the state table to MOTOR_DISABLED or COMM_DISABLED (the safe states) or on
        from there; returns the state reached (bounded)."""
        deadline = self.now() + self.settings.transition_timeout
        state = self.state()
        while state != target and self.now() < deadline:
            if target is S.COMM_DISABLED and state not in (S.COMM_ENABLED, S.MOTOR_READY,
                                                           S.MOTOR_DISABLED):
                step = S.MOTOR_DISABLED
            else:
                step = target
            state = int(self.request(step)["State"])
            if state != target:
                self.wait(0.1)
                state = self.state()
        return state

    # -- actuator traffic ----------------------------------------------------------------------

    def commands_of(self, bus: int, motor_id: int, since: float = -math.inf,
                    until: float = math.inf) -> list[LegFrame]:
        return self.link.frames(bus, motor_id, since, until)

    def replies_of(self, bus: int, motor_id: int | None = None, since: float = -math.inf,
                   until: float = math.inf) -> list[LegFrame]:
        frames = self.link.frames(bus, REPLY_ID, since, until)
        if motor_id is None:
            return frames
        return [f for f in frames if f.data[:1] == bytes((motor_id,))]

    def skip_without_motion(self) -> None:
        if not self.settings.motion:
            raise CheckSkipped("--no-motion")
