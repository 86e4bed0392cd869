"""A proxy that makes a correct lower computer look like wrong firmware, to test the suite.

It sits between the emulator's bus and the suite's bus: every frame the lower computer sends is
decoded with the project's codec, changed by the mutations (scale, offset, delay or drop a
signal or a message), re-encoded and forwarded; everything the suite sends goes back unchanged,
except that ``hold_commands`` keeps repeating the last MotionCommand for that long after the
suite stopped sending (a watchdog that reacts that much later), and ``command_delay`` delivers
each of them that much later (a busy host between the suite and a correct lower computer).

Frames reach the suite with the lower bus's timestamp (its kernel's reception time; later by
a mutation's ``delay``), as a CAN adapter stamps them on the wire: give it an upper bus that
keeps them (python-can's virtual bus with ``preserve_timestamps=True``). So the proxy's own
thread, starved on a busy host, does not put gaps into the suite's cycle times.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import can

from lowerbase.protocol.codec import Codec, default_codec


@dataclass(frozen=True)
class Mutation:
    """Change ``signal`` of ``message`` (all its frames, or those ``where`` selects):
    value * scale + offset; or delay the frame; or drop it."""

    message: str
    signal: str | None = None
    scale: float = 1.0
    offset: float = 0.0
    delay: float = 0.0  #: [s]
    drop: bool = False
    where: Callable[[dict[str, Any]], bool] | None = None
    #: any other change of the decoded values (returns the new values)
    transform: Callable[[dict[str, Any]], dict[str, Any]] | None = None


def _targets(values: dict[str, Any], signal: str) -> list[str]:
    """``signal`` itself, or its per-wheel forms in a multiplexed message (LeftCount...)."""
    return [k for k in values if k == signal or (k.endswith(signal)
                                                  and k[:-len(signal)] in ("Left", "Right"))]


def swap_wheels(values: dict[str, Any]) -> dict[str, Any]:
    """WheelFeedback of the left wheel reported as the right one and vice versa."""
    out = {}
    for k, v in values.items():
        if k.startswith("Left"):
            k = "Right" + k[4:]
        elif k.startswith("Right"):
            k = "Left" + k[5:]
        out[k] = v
    out["Wheel"] = 1 - int(values["Wheel"])
    return out


class MutatingProxy:
    def __init__(self, lower: can.BusABC, upper: can.BusABC,
                 mutations: Sequence[Mutation] = (), hold_commands: float = 0.0,
                 codec: Codec | None = None, command_delay: float = 0.0) -> None:
        self.lower, self.upper = lower, upper
        self.codec = codec or default_codec()
        self.mutations = list(mutations)
        self.hold_commands = hold_commands
        self.command_delay = command_delay
        self._lower_ids = frozenset(m.frame_id for m in self.codec if "Lower" in m.senders)
        self._motion_id = self.codec.message("MotionCommand").frame_id
        self._last_motion: tuple[float, can.Message] | None = None
        #: (due, sequence, frame, the bus it goes to)
        self._queue: list[tuple[float, int, can.Message, can.BusABC]] = []
        self._seq = itertools.count()
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mutating-proxy", daemon=True)
        self._thread.start()
        self._notifiers = [can.Notifier(lower, [self._from_lower], timeout=0.05),
                           can.Notifier(upper, [self._from_upper], timeout=0.05)]

    def set(self, mutations: Sequence[Mutation] = (), hold_commands: float = 0.0,
            command_delay: float = 0.0) -> None:
        with self._cond:
            self.mutations = list(mutations)
            self.hold_commands = hold_commands
            self.command_delay = command_delay

    def _later(self, delay: float, msg: can.Message, bus: can.BusABC) -> None:
        with self._cond:
            heapq.heappush(self._queue, (time.monotonic() + delay, next(self._seq), msg, bus))
            self._cond.notify()

    def _from_upper(self, msg: can.Message) -> None:
        if msg.arbitration_id in self._lower_ids and not msg.is_extended_id:
            return  # never loop the lower computer's frames back
        if msg.arbitration_id == self._motion_id and not msg.is_extended_id:
            with self._cond:
                self._last_motion = (time.monotonic(), msg)
        if self.command_delay > 0:
            self._later(self.command_delay, msg, self.lower)
        else:
            self._send(self.lower, msg)

    def _from_lower(self, msg: can.Message) -> None:
        if (msg.arbitration_id not in self._lower_ids or msg.is_extended_id
                or msg.is_error_frame or msg.is_remote_frame):
            return  # the suite's frames echoed by a multicast bus
        m = self.codec.message(msg.arbitration_id)
        with self._cond:
            mutations = [x for x in self.mutations if x.message == m.name]
        if not mutations or len(msg.data) != m.length:
            self._send(self.upper, msg)
            return
        values = dict(m.decode(bytes(msg.data), strict=False))
        delay = 0.0
        for x in mutations:
            if x.where is not None and not x.where(values):
                continue
            if x.drop:
                return
            delay = max(delay, x.delay)
            for name in _targets(values, x.signal) if x.signal is not None else ():
                values[name] = self._clip(m, name, float(values[name]) * x.scale + x.offset)
            if x.transform is not None:
                values = x.transform(values)
        out = can.Message(arbitration_id=msg.arbitration_id, data=m.encode(values),
                          is_extended_id=False, timestamp=msg.timestamp + delay)
        if delay > 0:
            self._later(delay, out, self.upper)
        else:
            self._send(self.upper, out)

    @staticmethod
    def _clip(m: Any, name: str, value: float) -> float:
        sig = m.signal(name)
        lo = sig.minimum if sig.minimum is not None else value
        hi = sig.maximum if sig.maximum is not None else value
        value = min(max(value, lo), hi)
        return round(value) if sig.scale == 1 and not sig.is_float else value

    def _run(self) -> None:
        """Release delayed frames, and repeat the last MotionCommand while held."""
        while not self._stop.is_set():
            now = time.monotonic()
            due: list[tuple[can.Message, can.BusABC]] = []
            repeat = None
            with self._cond:
                while self._queue and self._queue[0][0] <= now:
                    _, _, msg, bus = heapq.heappop(self._queue)
                    due.append((msg, bus))
                last = self._last_motion
                if (self.hold_commands > 0 and last is not None
                        and 0.02 <= now - last[0] <= self.hold_commands):
                    repeat = last[1]
                wait = min(0.005, self._queue[0][0] - now if self._queue else 0.005)
            for msg, bus in due:
                self._send(bus, msg)
            if repeat is not None:
                self._send(self.lower, repeat)
                self._stop.wait(0.02)
            else:
                self._stop.wait(max(0.0, wait))

    @staticmethod
    def _send(bus: can.BusABC, msg: can.Message) -> None:
        with contextlib.suppress(can.CanError):
            bus.send(msg)

    def close(self) -> None:
        for n in self._notifiers:
            n.stop()
        self._stop.set()
        self._thread.join(timeout=1.0)
