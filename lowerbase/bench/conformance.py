"""Protocol conformance suite: checks any lower computer on a live bus against the catalog.

The checks are data: a :class:`Check` has an id (``frame.WheelFeedback.cycle``,
``safety.watchdog``), a description and a function that takes a :class:`Context` (a
:class:`ConformanceClient` on the bus, the settings, shared state) and returns an
:class:`Outcome` (pass, fail, skip or error, a reason, measured values). :func:`registry`
builds them in run order:

- ``link``: the lower computer is on the bus (a Heartbeat arrives, ProtocolVersion matches).
- ``param``, ``version``, ``led``: the request/response pairs (and the LedCommand/LedState pair).
  They run while the passive observation window (``Settings.observe``) records every frame.
- ``frame.<Message>.<aspect>``: derived from the catalog for every periodic message the lower
  computer sends: ``present``, ``dlc``, ``range`` (every value decodes strictly), ``cycle``
  (mean interval within ``cycle_tolerance``, no gap above ``max_gap_cycles`` cycles plus the
  host's ``jitter``) and ``counter`` (+1 mod 16 per frame; per cycle where the catalog says the
  counter is shared, as for WheelFeedback; StatusCode has none).
- ``safety``: reboot (ControlCommand Reboot, BootCounter +1), standby after boot, MotionCommand
  ignored in standby, enable, watchdog stop, e-stop latch, standby.
- ``robust``: unknown IDs are ignored, frames of the wrong length and out-of-range values are
  survived and rejected MotionCommands flagged (StatusCode COMMAND_REJECTED).

Everything runs in real time against a live bus and every wait is bounded; a full run takes
about 15-25 s. At the end, parameters written by the suite are restored and the lower computer
is left in standby. Checks that turn the wheels (``Settings.motion``) expect a robot on blocks.
"""

from __future__ import annotations

import contextlib
import enum
import fnmatch
import itertools
import math
import struct
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import can

from lowerbase.bench.client import LowerClient, Received
from lowerbase.errors import ProtocolError
from lowerbase.protocol.codec import Codec, MessageCodec, default_codec
from lowerbase.protocol.status_codes import StatusBit

# -- outcomes and checks ------------------------------------------------------------------------


class Status(str, enum.Enum):
    PASS = "pass"
    FAIL = "fail"
    SKIP = "skip"
    ERROR = "error"  #: the check itself crashed (counts as a failure)


@dataclass(frozen=True)
class Outcome:
    status: Status
    detail: str = ""
    measured: Mapping[str, Any] = field(default_factory=dict)


def passed(detail: str = "", **measured: Any) -> Outcome:
    return Outcome(Status.PASS, detail, measured)


def failed(detail: str, **measured: Any) -> Outcome:
    return Outcome(Status.FAIL, detail, measured)


def skipped(detail: str, **measured: Any) -> Outcome:
    return Outcome(Status.SKIP, detail, measured)


class CheckFailed(Exception):
    """Raised inside a check to end it with a failure (see :func:`require`)."""

    def __init__(self, detail: str, **measured: Any) -> None:
        super().__init__(detail)
        self.detail = detail
        self.measured = measured


class CheckSkipped(Exception):
    """Raised inside a check to end it as skipped (a precondition that is not a failure)."""


def require(condition: object, detail: str, **measured: Any) -> None:
    """Fail the running check with ``detail`` unless ``condition`` holds."""
    if not condition:
        raise CheckFailed(detail, **measured)


CheckFunc = Callable[["Context"], Outcome]


@dataclass(frozen=True)
class Check:
    id: str  #: dotted, e.g. ``frame.WheelFeedback.cycle``; the first part is the group
    description: str
    func: CheckFunc

    @property
    def group(self) -> str:
        return self.id.split(".", 1)[0]


@dataclass(frozen=True)
class CheckResult:
    check: Check
    outcome: Outcome
    duration: float  #: [s]


@dataclass(frozen=True)
class Report:
    results: tuple[CheckResult, ...]
    duration: float  #: [s]

    def count(self, status: Status) -> int:
        return sum(r.outcome.status == status for r in self.results)

    @property
    def ok(self) -> bool:
        """True when no check failed or crashed (skips are allowed)."""
        return not any(r.outcome.status in (Status.FAIL, Status.ERROR) for r in self.results)

    def failed_ids(self) -> set[str]:
        return {r.check.id for r in self.results
                if r.outcome.status in (Status.FAIL, Status.ERROR)}

    def summary(self) -> str:
        n = len(self.results)
        return (f"{n} check{'s' if n != 1 else ''}: {self.count(Status.PASS)} passed, "
                f"{self.count(Status.FAIL)} failed, {self.count(Status.ERROR)} errors, "
                f"{self.count(Status.SKIP)} skipped in {self.duration:.1f} s")


@dataclass(frozen=True)
class Settings:
    """Tolerances and bounds of a run (defaults fit the catalog and a robot on blocks)."""

    observe: float = 5.0  #: [s] passive window for the per-frame checks (>= 3 slowest cycles)
    cycle_tolerance: float = 0.10  #: mean interval within +-10 % of the catalog cycle
    max_gap_cycles: float = 2.5  #: no gap between frames above this many cycles ...
    jitter: float = 0.05  #: [s] ... plus this allowance for the receiving host's timestamps
    link_timeout: float = 3.0  #: [s] to hear the lower computer at all
    reply_timeout: float = 1.0  #: [s] for a response or a state change
    boot_timeout: float = 10.0  #: [s] from ControlCommand Reboot to the boot-up Heartbeat
    watchdog_margin: float = 1.0  #: [s] beyond commandTimeout for the watchdog stop
    speed: float = 0.1  #: [m/s] the MotionCommand the suite sends (robot on blocks)
    motion: bool = True  #: False skips the checks that turn the wheels


# -- the client ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class RawFrame:
    t: float  #: reception time [s] (time.monotonic), comparable with Received.t
    stamp: float  #: the bus's timestamp [s] (kernel or adapter time where it has one)
    data: bytes


class ConformanceClient(LowerClient):
    """A :class:`LowerClient` that also keeps every raw frame of the lower computer's IDs
    (also those that do not decode), sends raw payloads, and serialises sends across threads."""

    def __init__(self, bus: can.BusABC, codec: Codec | None = None) -> None:
        self.raw: dict[int, list[RawFrame]] = {}
        self._raw_lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._lower_ids: frozenset[int] = frozenset()
        super().__init__(bus, codec)
        self._lower_ids = frozenset(m.frame_id for m in self.codec if "Lower" in m.senders)

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id in self._lower_ids and not (
            msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id
        ):
            frame = RawFrame(time.monotonic(), msg.timestamp or time.time(), bytes(msg.data))
            with self._raw_lock:
                self.raw.setdefault(msg.arbitration_id, []).append(frame)
        super().on_message_received(msg)

    def raw_frames(self, frame_id: int, since: float = 0.0, until: float = math.inf
                   ) -> list[RawFrame]:
        with self._raw_lock:
            return [f for f in self.raw.get(frame_id, ()) if since <= f.t <= until]

    def send(self, name: str, **values: Any) -> None:
        with self._send_lock:
            super().send(name, **values)

    def send_raw(self, frame_id: int, data: bytes, extended: bool = False) -> None:
        """Send any payload (wrong lengths, out-of-range values) on a standard (or extended)
        ID."""
        with self._send_lock:
            self.bus.send(can.Message(arbitration_id=frame_id, data=data,
                                      is_extended_id=extended))


# -- the context --------------------------------------------------------------------------------

#: RobotState and ControlMode numbers (the catalog's value tables)
BOOT, STANDBY, ACTIVE, EMERGENCY_STOP, FAULT = range(5)
CONTROL_CAN = 1
STILL = 0.2  #: a MotionState |Linear| below STILL * Settings.speed counts as standing still
MOTION_PERIOD = 0.02  #: [s] MotionCommand cycle the suite keeps while driving
#: [s] a SystemStatus received this long after a ControlCommand reflects it (frames in flight)
SETTLE = 0.03


class Context:
    """What every check gets: the client, the settings, and state shared between checks."""

    def __init__(self, client: ConformanceClient, settings: Settings) -> None:
        self.client = client
        self.codec = client.codec
        self.settings = settings
        self.t_start = time.monotonic()
        self.window_end = self.t_start + settings.observe
        self.linked = False
        self.param_cache: dict[int, float] = {}  #: index -> value read
        self.to_restore: dict[int, float] = {}  #: index -> value to write back at the end
        self.versions: dict[int, str] = {}
        self._reboot: tuple[float, Received] | CheckFailed | None = None
        self._last_control = -math.inf  #: time.monotonic() of the last ControlCommand

    # timing helpers

    def wait_until(self, condition: Callable[[], bool], timeout: float, poll: float = 0.02
                   ) -> bool:
        """Poll ``condition`` until it holds or ``timeout`` [s] passes."""
        deadline = time.monotonic() + timeout
        while True:
            if condition():
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(poll)

    def connect(self) -> None:
        """Wait (bounded) until any frame of the lower computer arrives, and until it has
        finished booting (it ignores requests while booting)."""
        self.linked = self.wait_until(lambda: bool(self.client.raw), self.settings.link_timeout)
        if self.linked:
            self.client.expect("SystemStatus", lambda v: v["RobotState"] != BOOT, since=0.0,
                               timeout=self.settings.boot_timeout)

    def observation(self, msg: MessageCodec) -> list[RawFrame]:
        """Frames of ``msg`` in the observation window (waits for the window to end)."""
        delay = self.window_end - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        return self.client.raw_frames(msg.frame_id, self.t_start, self.window_end)

    # state

    def latest(self, name: str, timeout: float | None = None) -> Received:
        """The newest ``name`` frame (waiting up to ``timeout``, default 2 cycles + 0.5 s)."""
        got = self.client.latest(name)
        if got is None:
            cycle = self.codec.message(name).cycle_time or 0.0
            wait = 2 * cycle + 0.5 if timeout is None else timeout
            got = self.client.expect(name, timeout=wait, since=0.0)
        require(got is not None, f"no {name} from the lower computer")
        assert got is not None
        return got

    def state(self) -> int:
        """RobotState from a SystemStatus that reflects the last ControlCommand sent."""
        since = self._last_control + SETTLE
        got = self.client.latest("SystemStatus")
        if got is None or got.t < since:
            cycle = self.codec.message("SystemStatus").cycle_time or 0.0
            got = self.client.expect("SystemStatus", since=since,
                                     timeout=2 * cycle + self.settings.reply_timeout)
        require(got is not None, "no SystemStatus from the lower computer")
        assert got is not None
        return int(got.values["RobotState"])

    def state_name(self, state: int) -> str:
        return self.codec.message("SystemStatus").signal("RobotState").choices.get(
            state, str(state))

    def control(self, command: str) -> float:
        """Send ControlCommand ``command``; returns the send time."""
        t = time.monotonic()
        self.client.send("ControlCommand", Command=command)
        self._last_control = t
        return t

    def expect_state(self, predicate: Callable[[dict[str, Any]], bool], since: float,
                     timeout: float | None = None) -> Received | None:
        return self.client.expect("SystemStatus", predicate, since=since,
                                  timeout=self.settings.reply_timeout if timeout is None
                                  else timeout)

    # The command is sent even when the state seems right already: a SystemStatus in flight
    # may be older than the last command, and commands are handled in the order sent.

    def ensure_standby(self) -> None:
        t = self.control("Standby")
        if not self.expect_state(lambda v: v["RobotState"] == STANDBY, t):
            raise CheckFailed(f"cannot reach Standby from {self.state_name(self.state())}")

    def ensure_active(self) -> None:
        t = self.control("EnableCanControl")
        if not self.expect_state(lambda v: v["RobotState"] == ACTIVE, t):
            raise CheckFailed(f"cannot enable from {self.state_name(self.state())}")

    def require_motion(self) -> None:
        if not self.settings.motion:
            raise CheckSkipped("turns the wheels (--no-motion)")

    @contextmanager
    def driving(self, linear: float, angular: float = 0.0) -> Iterator[MotionSender]:
        """Send MotionCommand every 20 ms in the background while the block runs."""
        sender = MotionSender(self.client, linear, angular)
        sender.start()
        try:
            yield sender
        finally:
            sender.stop()

    def wait_moving(self, timeout: float = 2.0) -> Received | None:
        """The first MotionState from now with Linear at least half the suite's speed."""
        half = 0.5 * self.settings.speed
        return self.client.expect("MotionState", lambda v: v["Linear"] >= half, timeout=timeout)

    def wait_still(self, since: float, timeout: float) -> Received | None:
        limit = STILL * self.settings.speed
        return self.client.expect(
            "MotionState", lambda v: abs(v["Linear"]) < limit and abs(v["Angular"]) < limit * 5,
            timeout=timeout, since=since)

    def max_speed(self, since: float, until: float = math.inf) -> float:
        """Largest |MotionState.Linear| received in [since, until] [m/s]."""
        return max((abs(f.values["Linear"]) for f in self.client.frames("MotionState", since)
                    if f.t <= until), default=0.0)

    def status_code(self, since: float = 0.0, timeout: float | None = None) -> int:
        """The newest StatusCode received after ``since`` (waiting for one)."""
        got = self.client.expect("StatusCode", since=since, timeout=self.settings.reply_timeout
                                 if timeout is None else timeout)
        require(got is not None, "no StatusCode")
        assert got is not None
        newest = self.client.latest("StatusCode")
        return int((newest or got).values["Code"])

    # requests

    def parameter_request(self, index: int, value: float | None = None) -> Received | None:
        """Read (``value`` None) or write a parameter; the ParameterResponse or None."""
        op = 0 if value is None else 1
        t = time.monotonic()
        self.client.send("ParameterRequest", Index=index, Op=op,
                         Value=0.0 if value is None else value)
        return self.client.expect(
            "ParameterResponse", lambda v: v["Index"] == index and v["Op"] == op, since=t,
            timeout=self.settings.reply_timeout)

    def parameter(self, name: str) -> float:
        """A parameter's value by name (read once, then cached)."""
        index = parameter_index(self.codec, name)
        if index not in self.param_cache:
            reply = self.parameter_request(index)
            require(reply is not None and reply.values["Result"] == 0,
                    f"cannot read parameter {name}")
            assert reply is not None
            self.param_cache[index] = float(reply.values["Value"])
        return self.param_cache[index]

    def reboot(self) -> tuple[float, Received]:
        """Reboot the lower computer once per run: (send time, the boot-up Heartbeat)."""
        if self._reboot is None:
            try:
                self._reboot = self._do_reboot()
            except CheckFailed as exc:
                self._reboot = exc
        if isinstance(self._reboot, CheckFailed):
            raise self._reboot
        return self._reboot

    def _do_reboot(self) -> tuple[float, Received]:
        boot = int(self.latest("Heartbeat").values["BootCounter"])
        t = self.control("Reboot")
        hb = self.client.expect("Heartbeat", lambda v: v["BootCounter"] != boot, since=t,
                                timeout=self.settings.boot_timeout)
        require(hb is not None, f"no Heartbeat with a new BootCounter within "
                f"{self.settings.boot_timeout:g} s of ControlCommand Reboot", boot_counter=boot)
        assert hb is not None
        self.param_cache.clear()  # a reboot reloads the stored parameters
        return t, hb

    def finish(self) -> list[str]:
        """Restore parameters the suite changed and leave the robot in standby; problems."""
        problems = []
        for index, value in sorted(self.to_restore.items()):
            reply = self.parameter_request(index, value)
            if reply is None or reply.values["Result"] != 0:
                problems.append(f"parameter {index} could not be restored to {value:g}")
        self.to_restore.clear()
        if self.linked:
            self.control("Standby")
        return problems


class MotionSender:
    """A background thread sending one MotionCommand every 20 ms, as a driver does."""

    def __init__(self, client: ConformanceClient, linear: float, angular: float) -> None:
        self.client = client
        self.linear, self.angular = linear, angular
        self.last_sent = -math.inf  #: time.monotonic() of the last MotionCommand
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="conformance-motion",
                                        daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        deadline = time.monotonic()
        while not self._stop.is_set():
            # a full transmit queue is no reason to stop: the next period tries again
            with contextlib.suppress(can.CanError):
                self.client.send("MotionCommand", Linear=self.linear, Angular=self.angular,
                                 Mode="Raw")
            self.last_sent = time.monotonic()
            self.sent += 1
            deadline += MOTION_PERIOD
            self._stop.wait(max(0.0, deadline - time.monotonic()))

    def stop(self) -> float:
        """Stop sending; returns the time of the last MotionCommand."""
        self._stop.set()
        self._thread.join(timeout=1.0)
        return self.last_sent


# -- catalog-derived facts ----------------------------------------------------------------------

#: signals that tell apart the frames of one cycle (the catalog's comments: one WheelFeedback
#: per wheel, one LedState per submodule of both strips)
ROW_KEYS: dict[str, tuple[str, ...]] = {
    "WheelFeedback": ("Wheel",),
    "LedState": ("Strip", "Submodule"),
}
#: messages sent only while a condition holds, with the StatusCode bit that announces its absence
CONDITIONAL: dict[str, StatusBit] = {
    "BmsPack": StatusBit.BMS_LINK_LOST,
    "BmsCell": StatusBit.BMS_LINK_LOST,
    "BmsCapacity": StatusBit.BMS_LINK_LOST,
    "BmsStatus": StatusBit.BMS_LINK_LOST,
    "BmsLife": StatusBit.BMS_LINK_LOST,
}


def periodic_lower_messages(codec: Codec) -> list[MessageCodec]:
    """Every periodic message the lower computer sends, in catalog order."""
    return [m for m in codec if m.is_periodic and "Lower" in m.senders]


def shared_counter(msg: MessageCodec) -> bool:
    """Whether the frames of one cycle share the counter (the Counter comment says so)."""
    return msg.has_counter and "shared" in msg.signal("Counter").comment.lower()


def protocol_version(codec: Codec) -> int:
    """The catalog's protocol version: the last word of its VERSION string."""
    words = (codec.database.version or "").split()
    return int(words[-1]) if words and words[-1].isdigit() else 1


def parameter_index(codec: Codec, name: str) -> int:
    table = codec.message("ParameterRequest").signal("Index").choices
    for index, text in table.items():
        if text == name:
            return index
    raise KeyError(name)


def parameter_limits() -> dict[int, tuple[str, float, float]]:
    """index -> (name, minimum, maximum): the documented parameter ranges."""
    from lowerbase.firmware_model.parameters import SPECS

    return {i: (s.name, s.minimum, s.maximum) for i, s in SPECS.items()}


def _close(a: float, b: float) -> bool:
    """Equal within float32 precision (parameter values travel as float32)."""
    return abs(a - b) <= 1e-6 * max(1.0, abs(a), abs(b))


# -- frame checks (derived from the catalog) ----------------------------------------------------


def _frames_or_skip(ctx: Context, msg: MessageCodec) -> list[RawFrame]:
    frames = ctx.observation(msg)
    if not frames:
        raise CheckSkipped(f"no {msg.name} frames (see frame.{msg.name}.present)")
    return frames


def check_present(msg: MessageCodec) -> CheckFunc:
    def run(ctx: Context) -> Outcome:
        frames = ctx.observation(msg)
        if frames:
            return passed(f"{len(frames)} frames in {ctx.settings.observe:g} s",
                          frames=len(frames))
        bit = CONDITIONAL.get(msg.name)
        if bit is not None and ctx.status_code() & bit:
            return skipped(f"not sent while StatusCode has {bit.name}")
        return failed(f"no {msg.name} in {ctx.settings.observe:g} s")
    return run


def check_dlc(msg: MessageCodec) -> CheckFunc:
    def run(ctx: Context) -> Outcome:
        frames = _frames_or_skip(ctx, msg)
        bad = [len(f.data) for f in frames if len(f.data) != msg.length]
        if bad:
            return failed(f"{len(bad)} of {len(frames)} frames with DLC {sorted(set(bad))} "
                          f"(catalog {msg.length})", wrong=len(bad), frames=len(frames))
        return passed(f"DLC {msg.length} in all {len(frames)} frames", frames=len(frames))
    return run


def check_range(msg: MessageCodec) -> CheckFunc:
    def run(ctx: Context) -> Outcome:
        frames = [f for f in _frames_or_skip(ctx, msg) if len(f.data) == msg.length]
        errors = []
        for f in frames:
            try:
                msg.decode(f.data)
            except ProtocolError as exc:
                errors.append(str(exc))
        if errors:
            return failed(f"{len(errors)} of {len(frames)} frames out of range: {errors[0]}",
                          out_of_range=len(errors))
        return passed(f"all {len(frames)} frames in range", frames=len(frames))
    return run


def cycle_stats(stamps: Sequence[float]) -> tuple[float, float]:
    """(mean interval, largest gap) [s] of increasing timestamps (at least two)."""
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    return (stamps[-1] - stamps[0]) / len(gaps), max(gaps)


def bursts(stamps: Sequence[float], cycle: float) -> list[float]:
    """Start times of the bursts of a message sent as several frames per cycle: a frame
    more than half a cycle after the start of the current burst starts the next one."""
    starts: list[float] = []
    for t in stamps:
        if not starts or t - starts[-1] > cycle / 2:
            starts.append(t)
    return starts


def check_cycle(msg: MessageCodec) -> CheckFunc:
    cycle = msg.cycle_time or 0.0

    def run(ctx: Context) -> Outcome:
        # every frame counts, also one of the wrong length: it was sent on time
        stamps = sorted(f.stamp for f in _frames_or_skip(ctx, msg))
        if msg.name in ROW_KEYS:
            stamps = bursts(stamps, cycle)
        s = ctx.settings
        if len(stamps) < 3:
            return skipped(f"fewer than 3 cycles in {s.observe:g} s (raise --observe)")
        gap_limit = s.max_gap_cycles * cycle + s.jitter
        worst_mean, worst_gap = cycle_stats(stamps)
        measured = {"cycle_ms": round(cycle * 1e3, 3), "mean_ms": round(worst_mean * 1e3, 3),
                    "max_gap_ms": round(worst_gap * 1e3, 3)}
        text = (f"mean {worst_mean * 1e3:.1f} ms (catalog {cycle * 1e3:g} ms), "
                f"max gap {worst_gap * 1e3:.1f} ms")
        if abs(worst_mean - cycle) > s.cycle_tolerance * cycle:
            return failed(f"{text}: mean off by more than {s.cycle_tolerance:.0%}", **measured)
        if worst_gap > gap_limit:
            return failed(f"{text}: gap above {gap_limit * 1e3:.0f} ms", **measured)
        return passed(text, **measured)
    return run


def counter_steps(counters: Sequence[int]) -> tuple[int, int, str]:
    """(steps, steps that are not +1 mod 16, an example) of a counter sequence."""
    bad, example = 0, ""
    for a, b in itertools.pairwise(counters):
        if b != (a + 1) & 0xF:
            bad += 1
            example = example or f"{a} -> {b}"
    return max(0, len(counters) - 1), bad, example


def shared_cycles(rows: Sequence[tuple[Any, int]]) -> tuple[list[int], int]:
    """Group (row key, counter) frames into cycles that share one counter.

    A new cycle starts when the counter changes or a row repeats. Returns the counter of each
    cycle and the number of inner cycles (not the first or last) that miss a row.
    """
    cycles: list[tuple[int, set[Any]]] = []
    for key, counter in rows:
        if not cycles or cycles[-1][0] != counter or key in cycles[-1][1]:
            cycles.append((counter, set()))
        cycles[-1][1].add(key)
    everyone = set().union(*(keys for _, keys in cycles)) if cycles else set()
    incomplete = sum(keys != everyone for _, keys in cycles[1:-1])
    return [c for c, _ in cycles], incomplete


def check_counter(msg: MessageCodec) -> CheckFunc:
    keys = ROW_KEYS.get(msg.name, ())
    shared = shared_counter(msg)

    def run(ctx: Context) -> Outcome:
        # a frame of the wrong length (frame.*.dlc) hides its counter: restart the sequence
        segments: list[list[dict[str, Any]]] = [[]]
        for f in _frames_or_skip(ctx, msg):
            if len(f.data) == msg.length:
                segments[-1].append(dict(msg.decode(f.data, strict=False)))
            elif segments[-1]:
                segments.append([])
        steps = bad = incomplete = 0
        example = ""
        for seg in segments:
            if shared:
                counters, missing = shared_cycles(
                    [(tuple(v[k] for k in keys), int(v["Counter"])) for v in seg])
                incomplete += missing
            else:
                counters = [int(v["Counter"]) for v in seg]
            n, b, e = counter_steps(counters)
            steps, bad, example = steps + n, bad + b, example or e
        require(steps >= 1, "fewer than 2 frames of the catalog length")
        what = "cycles" if shared else "frames"
        if incomplete:
            return failed(f"{incomplete} cycles whose frames do not share one counter",
                          incomplete=incomplete)
        if bad:
            return failed(f"{bad} of {steps} steps between {what} not +1 mod 16 "
                          f"(e.g. {example})", bad_steps=bad, steps=steps)
        return passed(f"+1 mod 16 over {steps} {what}" + (" (shared per cycle)" if shared
                                                          else ""), steps=steps)
    return run


def frame_checks(codec: Codec) -> list[Check]:
    """The per-frame checks of every periodic message the lower computer sends."""
    checks = []
    for msg in periodic_lower_messages(codec):
        cycle = f"{(msg.cycle_time or 0) * 1e3:g} ms"
        checks += [
            Check(f"frame.{msg.name}.present", f"{msg.name} is sent", check_present(msg)),
            Check(f"frame.{msg.name}.dlc", f"{msg.name} has DLC {msg.length}", check_dlc(msg)),
            Check(f"frame.{msg.name}.range", f"every {msg.name} value is within the catalog "
                  "range", check_range(msg)),
            Check(f"frame.{msg.name}.cycle", f"{msg.name} every {cycle}", check_cycle(msg)),
        ]
        if msg.has_counter:
            checks.append(Check(
                f"frame.{msg.name}.counter",
                f"{msg.name} counter +1 mod 16 per "
                + ("cycle, shared by the cycle's frames" if shared_counter(msg) else "frame"),
                check_counter(msg)))
    return checks


# -- link -----------------------------------------------------------------------------------------


def check_link(ctx: Context) -> Outcome:
    if not ctx.linked:
        return failed(f"nothing from the lower computer in {ctx.settings.link_timeout:g} s")
    hb = ctx.latest("Heartbeat")
    want = protocol_version(ctx.codec)
    got = int(hb.values["ProtocolVersion"])
    require(got == want, f"ProtocolVersion {got}, the catalog is version {want}")
    return passed(f"Heartbeat: boot #{hb.values['BootCounter']}, uptime "
                  f"{hb.values['Uptime']:.1f} s, protocol {got}",
                  boot_counter=hb.values["BootCounter"], uptime_s=hb.values["Uptime"],
                  protocol_version=got)


# -- parameters -----------------------------------------------------------------------------------

RESULT_ACK, RESULT_UNKNOWN_INDEX, RESULT_OUT_OF_RANGE = 0, 1, 2
#: the parameter the suite writes: it limits only the remote controller, never CAN motion
WRITE_PARAMETER = "joystickMaxLinear"


def _result_name(ctx: Context, result: int) -> str:
    return ctx.codec.message("ParameterResponse").signal("Result").choices.get(
        result, str(result))


def check_param_read(ctx: Context) -> Outcome:
    limits = parameter_limits()
    table = ctx.codec.message("ParameterRequest").signal("Index").choices
    values: dict[str, float] = {}
    problems: list[str] = []
    misses = 0
    for index, name in sorted(table.items()):
        reply = ctx.parameter_request(index)
        if reply is None:
            problems.append(f"{name}: no answer")
            misses += 1
            require(misses < 3, "no answer to 3 ParameterRequests: " + "; ".join(problems))
            continue
        result, value = int(reply.values["Result"]), float(reply.values["Value"])
        if result != RESULT_ACK:
            problems.append(f"{name}: {_result_name(ctx, result)}")
            continue
        ctx.param_cache[index] = value
        values[name] = value
        if index in limits:
            _, lo, hi = limits[index]
            if not lo <= value <= hi:
                problems.append(f"{name} = {value:g} outside [{lo:g}, {hi:g}]")
    if problems:
        return failed("; ".join(problems), **values)
    return passed(f"{len(values)} parameters acked, all in range", **values)


def _write_value(current: float, lo: float, hi: float) -> float:
    """A valid value other than ``current``: halfway towards the farther limit."""
    target = hi if current - lo < hi - current else lo
    return round((current + target) / 2, 3)


def check_param_write(ctx: Context) -> Outcome:
    index = parameter_index(ctx.codec, WRITE_PARAMETER)
    _, lo, hi = parameter_limits()[index]
    original = ctx.parameter(WRITE_PARAMETER)
    new = _write_value(original, lo, hi)
    ctx.to_restore.setdefault(index, original)
    reply = ctx.parameter_request(index, new)
    require(reply is not None, f"write {WRITE_PARAMETER} = {new:g}: no answer")
    assert reply is not None
    result, value = int(reply.values["Result"]), float(reply.values["Value"])
    require(result == RESULT_ACK, f"write {WRITE_PARAMETER} = {new:g}: "
            f"{_result_name(ctx, result)}")
    require(_close(value, new), f"write {WRITE_PARAMETER} = {new:g} answered {value:g}")
    back = ctx.parameter_request(index)
    require(back is not None and _close(float(back.values["Value"]), new),
            f"read back {WRITE_PARAMETER}: expected {new:g}, got "
            f"{back.values['Value'] if back else 'no answer'}")
    restore = ctx.parameter_request(index, original)
    require(restore is not None and restore.values["Result"] == RESULT_ACK
            and _close(float(restore.values["Value"]), original),
            f"restore {WRITE_PARAMETER} = {original:g} failed")
    ctx.to_restore.pop(index, None)
    return passed(f"{WRITE_PARAMETER}: {original:g} -> {new:g} -> {original:g}",
                  original=original, written=new)


def check_param_out_of_range(ctx: Context) -> Outcome:
    index = parameter_index(ctx.codec, WRITE_PARAMETER)
    _, lo, hi = parameter_limits()[index]
    original = ctx.parameter(WRITE_PARAMETER)
    bad = hi + (hi - lo)
    ctx.to_restore.setdefault(index, original)
    reply = ctx.parameter_request(index, bad)
    require(reply is not None, f"write {WRITE_PARAMETER} = {bad:g}: no answer")
    assert reply is not None
    result, value = int(reply.values["Result"]), float(reply.values["Value"])
    require(result == RESULT_OUT_OF_RANGE,
            f"write {WRITE_PARAMETER} = {bad:g} (limit {hi:g}): {_result_name(ctx, result)}, "
            "expected OutOfRange", result=result, value=value)
    require(_close(value, original),
            f"nack carries {value:g}, expected the value in force {original:g}")
    back = ctx.parameter_request(index)
    require(back is not None and _close(float(back.values["Value"]), original),
            f"{WRITE_PARAMETER} changed by a refused write")
    ctx.to_restore.pop(index, None)
    return passed(f"{WRITE_PARAMETER} = {bad:g} -> OutOfRange, {original:g} kept")


def check_param_unknown(ctx: Context) -> Outcome:
    known = ctx.codec.message("ParameterRequest").signal("Index").choices
    index = next(i for i in range(256) if i not in known)
    for value in (None, 1.0):
        reply = ctx.parameter_request(index, value)
        op = "read" if value is None else "write"
        require(reply is not None, f"{op} index {index}: no answer")
        assert reply is not None
        result = int(reply.values["Result"])
        require(result == RESULT_UNKNOWN_INDEX,
                f"{op} index {index}: {_result_name(ctx, result)}, expected UnknownIndex")
    return passed(f"read and write of index {index} -> UnknownIndex")


# -- versions -----------------------------------------------------------------------------------


def _assemble(frames: Iterable[Received]) -> dict[int, list[tuple[int, bool, bytes]]]:
    pieces: dict[int, list[tuple[int, bool, bytes]]] = {}
    for f in frames:
        v = f.values
        text = int(v["Text"]).to_bytes(6, "little")
        pieces.setdefault(int(v["Field"]), []).append((int(v["Sequence"]), bool(v["Last"]),
                                                       text))
    return pieces


def version_string(pieces: Sequence[tuple[int, bool, bytes]]) -> str | None:
    """The string of one field's pieces, or None while incomplete."""
    by_seq = {seq: (last, text) for seq, last, text in pieces}
    lasts = [seq for seq, (last, _) in by_seq.items() if last]
    if not lasts or set(by_seq) != set(range(lasts[0] + 1)):
        return None
    raw = b"".join(by_seq[i][1] for i in range(lasts[0] + 1))
    return raw.rstrip(b"\0").decode("ascii", errors="replace")


def _request_versions(ctx: Context, field_no: int, want: set[int]
                      ) -> dict[int, list[tuple[int, bool, bytes]]]:
    t = time.monotonic()
    ctx.client.send("VersionRequest", Field=field_no)

    def complete() -> bool:
        got = _assemble(ctx.client.frames("VersionResponse", t))
        return all(f in got and version_string(got[f]) is not None for f in want)

    ctx.wait_until(complete, 2 * ctx.settings.reply_timeout)
    time.sleep(0.1)  # late or duplicate pieces would show up now
    return _assemble(ctx.client.frames("VersionResponse", t))


def _check_pieces(field_name: str, pieces: list[tuple[int, bool, bytes]]) -> str:
    seqs = [p[0] for p in pieces]
    require(len(seqs) == len(set(seqs)), f"{field_name}: repeated pieces {sorted(seqs)}")
    text = version_string(pieces)
    require(text is not None, f"{field_name}: incomplete (pieces {sorted(seqs)})")
    assert text is not None
    require(text and text.isprintable() and text.isascii(),
            f"{field_name}: not printable ASCII: {text!r}")
    return text


def check_version_all(ctx: Context) -> Outcome:
    names = ctx.codec.message("VersionResponse").signal("Field").choices
    got = _request_versions(ctx, 0, set(names))
    missing = [names[f] for f in names if f not in got]
    require(not missing, f"no {', '.join(missing)}")
    for f, pieces in sorted(got.items()):
        require(f in names, f"unknown Field {f}")
        ctx.versions[f] = _check_pieces(names[f], pieces)
    shown = {names[f]: text for f, text in sorted(ctx.versions.items())}
    return passed(", ".join(shown.values()), **shown)


def check_version_field(ctx: Context) -> Outcome:
    names = ctx.codec.message("VersionResponse").signal("Field").choices
    field_no = 2  # SoftwareVersion
    got = _request_versions(ctx, field_no, {field_no})
    require(field_no in got, f"no {names[field_no]}")
    others = sorted(names.get(f, str(f)) for f in got if f != field_no)
    require(not others, f"asked for {names[field_no]}, also got {', '.join(others)}")
    text = _check_pieces(names[field_no], got[field_no])
    if field_no in ctx.versions:
        require(text == ctx.versions[field_no],
                f"{text!r} differs from {ctx.versions[field_no]!r} of VersionRequest All")
    return passed(f"{names[field_no]} only: {text}", text=text)


# -- LEDs -----------------------------------------------------------------------------------------

LED_SIGNALS = ("Urgency", "Abnormal", "Normal", "Color")


def check_led(ctx: Context) -> Outcome:
    strip, sub = 0, 8
    state = ctx.codec.message("LedState")
    wait = 2.5 * (state.cycle_time or 1.0)

    def row(v: dict[str, Any]) -> bool:
        return bool(v["Strip"] == strip and v["Submodule"] == sub)

    before = ctx.client.expect("LedState", row, since=0.0, timeout=wait)
    require(before is not None, f"no LedState of strip {strip} submodule {sub}")
    assert before is not None
    want = {"Urgency": 0, "Abnormal": 0, "Normal": 128, "Color": 0x123456}  # Forward, a colour
    if all(before.values[k] == want[k] for k in LED_SIGNALS):
        want["Color"] = 0x654321
    t = time.monotonic()
    ctx.client.send("LedCommand", Strip=strip, Submodule=sub, **want)
    shown = ctx.client.expect(
        "LedState", lambda v: row(v) and all(v[k] == want[k] for k in LED_SIGNALS), since=t,
        timeout=wait)
    latency = shown.t - t if shown else None
    old = {k: before.values[k] for k in LED_SIGNALS}
    t = time.monotonic()
    ctx.client.send("LedCommand", Strip=strip, Submodule=sub, **old)
    require(shown is not None, f"LedCommand {want} not shown by LedState within {wait:g} s")
    restored = ctx.client.expect(
        "LedState", lambda v: row(v) and all(v[k] == old[k] for k in LED_SIGNALS), since=t,
        timeout=wait)
    require(restored is not None, "LedState did not return to its previous value")
    return passed(f"strip {strip} submodule {sub} shown after {latency:.2f} s and restored",
                  latency_s=round(latency or 0.0, 3))


# -- safety ---------------------------------------------------------------------------------------


def check_reboot(ctx: Context) -> Outcome:
    before = int(ctx.latest("Heartbeat").values["BootCounter"])
    t, hb = ctx.reboot()
    boot = int(hb.values["BootCounter"])
    require(boot == (before + 1) & 0xFFFF, f"BootCounter {before} -> {boot}, expected +1")
    uptime = float(hb.values["Uptime"])
    require(uptime < 5.0, f"boot-up Heartbeat with uptime {uptime:.1f} s")
    return passed(f"BootCounter {before} -> {boot}, boot-up Heartbeat after {hb.t - t:.2f} s",
                  reboot_s=round(hb.t - t, 3), boot_counter=boot)


def check_standby_after_boot(ctx: Context) -> Outcome:
    try:
        _, hb = ctx.reboot()
    except CheckFailed as exc:
        raise CheckSkipped(f"no reboot ({exc.detail})") from None
    standby = ctx.expect_state(lambda v: v["RobotState"] == STANDBY, hb.t, timeout=3.0)
    require(standby is not None, "no Standby within 3 s of the boot-up Heartbeat")
    assert standby is not None
    for f in ctx.client.frames("SystemStatus", hb.t):
        v = f.values
        if f.t <= standby.t and (v["RobotState"] not in (BOOT, STANDBY) or v["ControlMode"]):
            raise CheckFailed(f"after boot: RobotState {ctx.state_name(v['RobotState'])}, "
                              f"ControlMode {v['ControlMode']}")
    return passed(f"Standby {standby.t - hb.t:.2f} s after the boot-up Heartbeat",
                  standby_s=round(standby.t - hb.t, 3))


def check_standby_ignores_motion(ctx: Context) -> Outcome:
    ctx.require_motion()
    ctx.ensure_standby()
    t0 = time.monotonic()
    with ctx.driving(ctx.settings.speed):
        time.sleep(0.6)
    t1 = time.monotonic()
    time.sleep(0.2)
    fastest = ctx.max_speed(t0)
    states = {int(f.values["RobotState"]) for f in ctx.client.frames("SystemStatus", t0)}
    codes = [int(f.values["Code"]) for f in ctx.client.frames("StatusCode", t0)]
    require(fastest < STILL * ctx.settings.speed,
            f"moved at {fastest:.3f} m/s on MotionCommand in Standby", max_speed=fastest)
    require(states == {STANDBY}, f"RobotState {sorted(map(ctx.state_name, states))} "
            "on MotionCommand in Standby")
    require(any(c & StatusBit.COMMAND_IN_STANDBY for c in codes),
            "StatusCode COMMAND_IN_STANDBY not set")
    return passed(f"{t1 - t0:.1f} s of MotionCommand ignored, COMMAND_IN_STANDBY set",
                  max_speed=fastest)


def check_enable(ctx: Context) -> Outcome:
    ctx.ensure_standby()
    t = ctx.control("EnableCanControl")
    active = ctx.expect_state(lambda v: v["RobotState"] == ACTIVE, t)
    require(active is not None, "EnableCanControl: RobotState did not become Active")
    assert active is not None
    require(active.values["ControlMode"] == CONTROL_CAN,
            f"Active with ControlMode {active.values['ControlMode']}, expected Can")
    latency = active.t - t
    if not ctx.settings.motion:
        return passed(f"Active after {latency:.2f} s (motion not checked: --no-motion)",
                      enable_s=round(latency, 3))
    t = time.monotonic()
    with ctx.driving(ctx.settings.speed):
        moving = ctx.wait_moving()
    require(moving is not None, f"MotionCommand {ctx.settings.speed:g} m/s not followed "
            f"within 2 s (max {ctx.max_speed(t):.3f} m/s)")
    assert moving is not None
    return passed(f"Active after {latency:.2f} s, follows MotionCommand after "
                  f"{moving.t - t:.2f} s", enable_s=round(latency, 3),
                  follow_s=round(moving.t - t, 3))


def check_watchdog(ctx: Context) -> Outcome:
    ctx.require_motion()
    timeout = ctx.parameter("commandTimeout")
    ctx.ensure_active()
    limit = timeout + ctx.settings.watchdog_margin
    try:
        with ctx.driving(ctx.settings.speed) as sender:
            require(ctx.wait_moving() is not None, "did not move on MotionCommand")
        t_stop = sender.last_sent
        flag = ctx.expect_state(lambda v: v["WatchdogStop"] == 1, t_stop,
                                timeout=limit - (time.monotonic() - t_stop))
        still = ctx.wait_still(t_stop, timeout=limit - (time.monotonic() - t_stop))
        bit = ctx.client.expect("StatusCode", lambda v: v["Code"] & StatusBit.WATCHDOG_STOP,
                                since=t_stop, timeout=0.5)
        require(flag is not None, f"no WatchdogStop within {limit:.2f} s of the last "
                f"MotionCommand (commandTimeout {timeout:g} s); moving at "
                f"{abs(ctx.latest('MotionState').values['Linear']):.3f} m/s",
                command_timeout_s=timeout)
        assert flag is not None
        require(still is not None, f"MotionState not 0 within {limit:.2f} s")
        assert still is not None
        require(bit is not None, "SystemStatus WatchdogStop without StatusCode WATCHDOG_STOP")
        latency = flag.t - t_stop
        require(latency >= timeout - 0.05,
                f"WatchdogStop after {latency:.3f} s, before commandTimeout {timeout:g} s")
        return passed(f"WatchdogStop {latency:.2f} s and standstill {still.t - t_stop:.2f} s "
                      f"after the last MotionCommand (commandTimeout {timeout:g} s)",
                      command_timeout_s=timeout, watchdog_s=round(latency, 3),
                      stop_s=round(still.t - t_stop, 3))
    finally:
        ctx.client.send("MotionCommand", Linear=0.0, Angular=0.0, Mode="Raw")
        ctx.control("Standby")


def check_estop(ctx: Context) -> Outcome:
    s = ctx.settings
    ctx.ensure_active()
    set_sent = False
    try:
        with ctx.driving(s.speed if s.motion else 0.0):
            if s.motion:
                require(ctx.wait_moving() is not None, "did not move on MotionCommand")
            t = ctx.control("EStopSet")
            set_sent = True
            stopped = ctx.expect_state(
                lambda v: v["RobotState"] == EMERGENCY_STOP and v["EStop"] == 1, t)
            require(stopped is not None, "EStopSet: no EmergencyStop with EStop 1 "
                    f"(RobotState {ctx.state_name(ctx.state())})")
            assert stopped is not None
            require(ctx.client.expect("StatusCode",
                                      lambda v: v["Code"] & StatusBit.ESTOP_COMMAND, since=t,
                                      timeout=s.reply_timeout),
                    "EStopSet: StatusCode ESTOP_COMMAND not set")
            if s.motion:
                still = ctx.wait_still(t, timeout=1.5)
                require(still is not None, "EStopSet: still moving after 1.5 s while "
                        "MotionCommands keep coming")
            t_enable = ctx.control("EnableCanControl")
            time.sleep(0.5)
            states = {int(f.values["RobotState"])
                      for f in ctx.client.frames("SystemStatus", t_enable)}
            require(states == {EMERGENCY_STOP}, "EnableCanControl released the e-stop "
                    f"(RobotState {sorted(map(ctx.state_name, states))})")
            if s.motion:
                fastest = ctx.max_speed(t_enable + 0.1)
                require(fastest < STILL * s.speed,
                        f"moved at {fastest:.3f} m/s while e-stopped")
        t_release = ctx.control("EStopRelease")
        released = ctx.expect_state(
            lambda v: v["RobotState"] == STANDBY and v["EStop"] == 0, t_release)
        require(released is not None, "EStopRelease: no Standby with EStop 0 "
                f"(RobotState {ctx.state_name(ctx.state())})")
        set_sent = False
        code = ctx.status_code(since=time.monotonic())
        require(not code & (StatusBit.ESTOP_BUTTON | StatusBit.ESTOP_COMMAND),
                f"StatusCode {code:#x} still has an e-stop bit after EStopRelease")
        return passed(f"stopped in {stopped.t - t:.2f} s, latched against EnableCanControl, "
                      "released to Standby", estop_s=round(stopped.t - t, 3))
    finally:
        if set_sent:
            ctx.control("EStopRelease")
        ctx.control("Standby")


def check_standby(ctx: Context) -> Outcome:
    ctx.ensure_active()
    t = ctx.control("Standby")
    got = ctx.expect_state(lambda v: v["RobotState"] == STANDBY and v["ControlMode"] == 0, t)
    require(got is not None, "ControlCommand Standby: no Standby with ControlMode None")
    assert got is not None
    return passed(f"Standby after {got.t - t:.2f} s", standby_s=round(got.t - t, 3))


# -- robustness -----------------------------------------------------------------------------------

UNKNOWN_IDS = (0x001, 0x123, 0x555, 0x7FF)


def _snapshot(ctx: Context) -> tuple[int, int, int]:
    """(BootCounter, RobotState, StatusCode) now."""
    return (int(ctx.latest("Heartbeat").values["BootCounter"]), ctx.state(),
            ctx.status_code(since=time.monotonic()))


def _survived(ctx: Context, before: tuple[int, int, int], since: float,
              allowed_bits: int = 0) -> tuple[int, int, int]:
    """Require Heartbeats after ``since`` with the same BootCounter and no state change."""
    hb_cycle = ctx.codec.message("Heartbeat").cycle_time or 0.5
    hb = ctx.client.expect("Heartbeat", since=since, timeout=2.5 * hb_cycle + 0.5)
    require(hb is not None, "Heartbeat stopped")
    assert hb is not None
    boot, state, code = before
    require(int(hb.values["BootCounter"]) == boot,
            f"rebooted (BootCounter {boot} -> {hb.values['BootCounter']})")
    now_state = ctx.state()
    require(now_state == state,
            f"RobotState {ctx.state_name(state)} -> {ctx.state_name(now_state)}")
    new_code = ctx.status_code(since=time.monotonic())
    appeared = new_code & ~code & ~allowed_bits
    require(not appeared, f"StatusCode gained {StatusBit(appeared)!r}")
    return int(hb.values["BootCounter"]), now_state, new_code


def _clear_rejected(ctx: Context) -> None:
    """FaultClear, and require COMMAND_REJECTED to be gone afterwards."""
    t = ctx.control("FaultClear")
    got = ctx.client.expect(
        "StatusCode", lambda v: not v["Code"] & StatusBit.COMMAND_REJECTED, since=t + 0.01,
        timeout=ctx.settings.reply_timeout)
    require(got is not None, "FaultClear did not clear COMMAND_REJECTED")


def _expect_rejected(ctx: Context, since: float, what: str) -> None:
    got = ctx.client.expect("StatusCode", lambda v: v["Code"] & StatusBit.COMMAND_REJECTED,
                            since=since, timeout=ctx.settings.reply_timeout)
    require(got is not None, f"{what}: StatusCode COMMAND_REJECTED not set")


def check_unknown_ids(ctx: Context) -> Outcome:
    before = _snapshot(ctx)
    t = time.monotonic()
    for i in range(10):
        for frame_id in UNKNOWN_IDS:
            ctx.client.send_raw(frame_id, bytes([0xFF, i, 0x00, 0x55, 0xAA, 0x01, 0x02, 0x7F]))
        time.sleep(0.005)
    hz = len(ctx.client.frames("SystemStatus", t))
    _survived(ctx, before, t)
    return passed(f"{10 * len(UNKNOWN_IDS)} frames on IDs "
                  f"{', '.join(f'{i:#05x}' for i in UNKNOWN_IDS)} ignored", frames=hz)


def check_extended_ids(ctx: Context) -> Outcome:
    """Extended frames whose 29-bit IDs equal catalog IDs belong to other devices."""
    before = _snapshot(ctx)
    control = ctx.codec.message("ControlCommand")
    t = time.monotonic()
    try:
        for command in ("Reboot", "EStopSet"):
            number = control.choice_number("Command", command)
            ctx.client.send_raw(control.frame_id, bytes([number]), extended=True)
    except can.CanOperationError as exc:  # the serial framing carries 11-bit IDs only
        return skipped(f"this transport cannot send extended frames ({exc})")
    _survived(ctx, before, t)
    return passed("extended frames with the IDs of ControlCommand Reboot and EStopSet ignored")


def check_bad_dlc(ctx: Context) -> Outcome:
    _clear_rejected(ctx)
    before = _snapshot(ctx)
    motion = ctx.codec.message("MotionCommand")
    good = motion.encode({"Linear": 0.0, "Angular": 0.0, "Mode": 0, "Counter": 0})
    t = time.monotonic()
    ctx.client.send_raw(motion.frame_id, good[:-1])
    ctx.client.send_raw(motion.frame_id, good + b"\0\0")
    _expect_rejected(ctx, t, f"MotionCommand with DLC {len(good) - 1} and {len(good) + 2}")
    ctx.client.send_raw(ctx.codec.message("ControlCommand").frame_id, b"")
    ctx.client.send_raw(ctx.codec.message("ParameterRequest").frame_id, b"\x00\x00")
    ctx.client.send_raw(ctx.codec.message("VersionRequest").frame_id, bytes(8))
    _survived(ctx, before, t, allowed_bits=StatusBit.COMMAND_REJECTED)
    _clear_rejected(ctx)
    return passed("wrong-length MotionCommand flagged COMMAND_REJECTED; ControlCommand, "
                  "ParameterRequest, VersionRequest of wrong length survived")


def check_out_of_range(ctx: Context) -> Outcome:
    _clear_rejected(ctx)
    before = _snapshot(ctx)
    motion = ctx.codec.message("MotionCommand")
    data = bytearray(motion.encode({"Linear": 0.0, "Angular": 0.0, "Mode": 0, "Counter": 0}))
    struct.pack_into("<h", data, 0, 0x7FFF)  # Linear 32.767 m/s, beyond the catalog's 3 m/s
    t = time.monotonic()
    ctx.client.send_raw(motion.frame_id, bytes(data))
    _expect_rejected(ctx, t, "MotionCommand Linear 32.767 m/s")
    control = ctx.codec.message("ControlCommand").frame_id
    ctx.client.send_raw(control, b"\x00")  # Command 0 and 255: outside [1, 7]
    ctx.client.send_raw(control, b"\xff")
    ctx.client.send_raw(ctx.codec.message("VersionRequest").frame_id, b"\x09")
    _survived(ctx, before, t, allowed_bits=StatusBit.COMMAND_REJECTED)
    _clear_rejected(ctx)
    return passed("MotionCommand out of range flagged COMMAND_REJECTED; ControlCommand 0 and "
                  "255, VersionRequest 9 survived")


# -- the registry and the runner ----------------------------------------------------------------


def registry(codec: Codec | None = None) -> list[Check]:
    """Every check, in run order."""
    codec = codec or default_codec()
    return [
        Check("link.heartbeat", "the lower computer is on the bus and speaks this catalog",
              check_link),
        Check("param.read", "every parameter index is acked with a value in range",
              check_param_read),
        Check("param.write", f"a written value ({WRITE_PARAMETER}) is acked and read back",
              check_param_write),
        Check("param.out_of_range", "an out-of-range write is nacked OutOfRange",
              check_param_out_of_range),
        Check("param.unknown_index", "an unknown index is nacked UnknownIndex",
              check_param_unknown),
        Check("version.all", "VersionRequest All: four complete strings", check_version_all),
        Check("version.field", "VersionRequest of one field: only that string",
              check_version_field),
        Check("led.command", "LedCommand is shown by LedState", check_led),
        *frame_checks(codec),
        Check("safety.reboot", "ControlCommand Reboot: boot-up Heartbeat, BootCounter +1",
              check_reboot),
        Check("safety.standby_after_boot", "standby after boot", check_standby_after_boot),
        Check("safety.standby_ignores_motion", "MotionCommand ignored and flagged in standby",
              check_standby_ignores_motion),
        Check("safety.enable", "EnableCanControl: Active, MotionCommand followed",
              check_enable),
        Check("safety.watchdog", "no MotionCommand for commandTimeout: WatchdogStop, braked "
              "to 0", check_watchdog),
        Check("safety.estop", "EStopSet stops and latches, EStopRelease -> Standby",
              check_estop),
        Check("safety.standby", "ControlCommand Standby from Active", check_standby),
        Check("robust.unknown_id", "frames on unknown IDs are ignored", check_unknown_ids),
        Check("robust.extended_id", "extended frames on catalog IDs are ignored",
              check_extended_ids),
        Check("robust.bad_dlc", "frames of the wrong length are survived, MotionCommand "
              "flagged", check_bad_dlc),
        Check("robust.out_of_range", "out-of-range values are survived, MotionCommand flagged",
              check_out_of_range),
    ]


def select(checks: Sequence[Check], patterns: Iterable[str]) -> list[Check]:
    """The checks whose id matches any of the shell patterns (comma-separated allowed)."""
    pats = [p.strip() for text in patterns for p in text.split(",") if p.strip()]
    if not pats:
        return list(checks)
    return [c for c in checks if any(fnmatch.fnmatchcase(c.id, p) for p in pats)]


def run_check(check: Check, ctx: Context) -> Outcome:
    """Run one check; failures and skips raised inside become outcomes."""
    try:
        return check.func(ctx)
    except CheckFailed as exc:
        return Outcome(Status.FAIL, exc.detail, exc.measured)
    except CheckSkipped as exc:
        return Outcome(Status.SKIP, str(exc))
    except (can.CanError, ProtocolError, OSError) as exc:
        return Outcome(Status.ERROR, f"{type(exc).__name__}: {exc}")


def run_suite(
    client: ConformanceClient, checks: Sequence[Check], settings: Settings | None = None,
    on_result: Callable[[CheckResult], None] | None = None,
) -> Report:
    """Run ``checks`` in order against the lower computer behind ``client``."""
    settings = settings or Settings()
    start = time.monotonic()
    ctx = Context(client, settings)
    results: list[CheckResult] = []
    try:
        ctx.connect()
        for check in checks:
            t = time.monotonic()
            if ctx.linked or check.id == "link.heartbeat":
                outcome = run_check(check, ctx)
            else:
                outcome = skipped("no lower computer on the bus (see link.heartbeat)")
            result = CheckResult(check, outcome, time.monotonic() - t)
            results.append(result)
            if on_result is not None:
                on_result(result)
    finally:
        problems = ctx.finish()
    if problems:
        check = Check("cleanup", "parameters restored, standby", lambda _: failed(""))
        results.append(CheckResult(check, failed("; ".join(problems)), 0.0))
        if on_result is not None:
            on_result(results[-1])
    return Report(tuple(results), time.monotonic() - start)


# -- JUnit XML ------------------------------------------------------------------------------------


def junit_xml(report: Report, name: str = "lowerbase.conformance") -> ET.ElementTree:
    """The report as JUnit XML (testsuites/testsuite/testcase with failure, error, skipped)."""
    suites = ET.Element("testsuites", name=name)
    suite = ET.SubElement(
        suites, "testsuite", name=name, tests=str(len(report.results)),
        failures=str(report.count(Status.FAIL)), errors=str(report.count(Status.ERROR)),
        skipped=str(report.count(Status.SKIP)), time=f"{report.duration:.3f}",
        timestamp=time.strftime("%Y-%m-%dT%H:%M:%S"))
    for r in report.results:
        classname = f"{name}.{r.check.id.rsplit('.', 1)[0]}"
        case = ET.SubElement(suite, "testcase", classname=classname, name=r.check.id,
                             time=f"{r.duration:.3f}")
        o = r.outcome
        if o.status in (Status.FAIL, Status.ERROR):
            tag = "failure" if o.status == Status.FAIL else "error"
            el = ET.SubElement(case, tag, message=o.detail, type=f"conformance.{tag}")
            el.text = f"{r.check.description}: {o.detail}"
        elif o.status == Status.SKIP:
            ET.SubElement(case, "skipped", message=o.detail)
        if o.measured:
            out = ET.SubElement(case, "system-out")
            out.text = "\n".join(f"{k} = {v}" for k, v in o.measured.items())
    ET.indent(suites)
    return ET.ElementTree(suites)
