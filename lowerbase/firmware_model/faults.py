"""Fault injection: what can be broken in a running lower computer, by API or CLI.

A fault is named by a short spec, the same on the command line and in scenarios::

    stall:left             the left wheel is blocked (current rises, stall, then a driver fault)
    overcurrent:right      the right driver reports over-current (it brakes, then faults)
    encoder:left           the left encoder loses pulses (the count freezes)
    imu-freeze             the IMU repeats its last sample
    imu-bias:0.02          a gyro z bias step [rad/s] (invisible to the firmware)
    silence                the lower computer stops sending (bus silence)
    drop:0.1               each outgoing frame is lost with probability 0.1
    delay:0.05             each outgoing frame leaves 0.05 s late
    corrupt:0.01           each outgoing frame is cut one byte short with probability 0.01
    estop                  the emergency-stop button is pressed (released when the fault ends)
    bms-silence            the BMS stops answering the lower computer's polls
    defect:NAME            a firmware bug, for testing the conformance suite (see DEFECTS)

``@T`` starts it T seconds after boot and ``+D`` ends it D seconds later
(``stall:left@5+2``); without them a fault starts at once and lasts until cleared.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass

from lowerbase.errors import ConfigError

#: deliberate firmware bugs (``defect:NAME``): each breaks what ``lowerbase conformance`` checks
DEFECTS: dict[str, str] = {
    "no-watchdog": "the command watchdog never fires (the last MotionCommand stays in force)",
    "counter-stuck": "rolling counters never advance",
    "slow-heartbeat": "Heartbeat at twice its cycle time",
    "ignore-estop": "ControlCommand EStopSet is ignored",
    "param-no-nack": "out-of-range parameter writes are acked (and ignored) instead of nacked",
}

#: fault kind -> (argument description or None, whether an argument is required)
KINDS: dict[str, tuple[str | None, bool]] = {
    "stall": ("left|right", True),
    "overcurrent": ("left|right", True),
    "encoder": ("left|right", True),
    "imu-freeze": (None, False),
    "imu-bias": ("rad/s", True),
    "silence": (None, False),
    "drop": ("probability 0..1", True),
    "delay": ("seconds", True),
    "corrupt": ("probability 0..1", True),
    "estop": (None, False),
    "bms-silence": (None, False),
    "defect": ("|".join(DEFECTS), True),
}

_SPEC = re.compile(
    r"^(?P<kind>[a-z-]+)(?::(?P<arg>[^@+]+))?(?:@(?P<start>[^+]*))?(?:\+(?P<dur>.*))?$"
)


@dataclass(frozen=True)
class Fault:
    kind: str
    arg: str | None = None
    start: float = 0.0  #: [s] after boot
    duration: float | None = None  #: [s], None = until cleared

    @property
    def value(self) -> float:
        """The numeric argument (imu-bias, drop, delay, corrupt)."""
        return float(self.arg) if self.arg is not None else 0.0

    @property
    def side(self) -> str:
        return self.arg or ""

    def active(self, t_since_boot: float) -> bool:
        if t_since_boot < self.start:
            return False
        return self.duration is None or t_since_boot < self.start + self.duration

    def __str__(self) -> str:
        text = self.kind + (f":{self.arg}" if self.arg is not None else "")
        if self.start:
            text += f"@{self.start:g}"
        if self.duration is not None:
            text += f"+{self.duration:g}"
        return text


#: faults whose hook acts when their value changes, not in every period they are active: the
#: gyro bias step (Mcu._apply_bias adds it once, before a period; the IMU model then carries
#: it as data)
ONCE = frozenset({"imu-bias"})
#: faults every period takes as data (the encoders' dropout, the IMU's freeze, the drivers'
#: injected over-current and the wheels' blocked flags, set per period from the active
#: faults: Mcu.step), without the fault hooks
DATA = frozenset({"encoder", "imu-freeze", "overcurrent", "stall"})
#: faults active in a period without the fault hooks; the others turn the hooks on (still
#: compiled: fastkernel.KernelLoop.set_hooks)
LEAN = ONCE | DATA


def any_active(faults: Iterable[Fault], t_since_boot: float,
               skip: frozenset[str] = frozenset()) -> bool:
    """Whether one of ``faults`` (but those of a kind in ``skip``) is active at
    ``t_since_boot`` [s] (a fault armed for later, or over, changes nothing in a control
    period: the lean path takes it)."""
    return any(f.active(t_since_boot) for f in faults if f.kind not in skip)


def quiet_periods(faults: Iterable[Fault], t_since_boot: float, dt: float, most: int) -> int:
    """How many control periods of ``dt`` from ``t_since_boot`` on (at most ``most``) surely
    have none of ``faults`` active: 0 when one is active now; before one that starts later, a
    period fewer than fit (the simulated clock sums its steps: a period's time is t + k dt
    only to rounding)."""
    n = most
    for f in faults:
        if f.active(t_since_boot):
            return 0
        if f.start > t_since_boot:
            n = min(n, max(0, math.floor((f.start - t_since_boot) / dt) - 1))
    return n


def parse_fault(spec: str) -> Fault:
    """Parse a fault spec (see the module docstring); ConfigError with the usage otherwise."""
    m = _SPEC.match(spec.strip())
    usage = "; known: " + ", ".join(
        k + (f":<{a}>" if a else "") for k, (a, _) in KINDS.items()
    )
    if not m or m["kind"] not in KINDS:
        raise ConfigError(f"unknown fault {spec!r}{usage}")
    kind, arg = m["kind"], m["arg"]
    what, required = KINDS[kind]
    if required and arg is None:
        raise ConfigError(f"fault {spec!r} needs an argument ({what})")
    if what is None and arg is not None:
        raise ConfigError(f"fault {kind!r} takes no argument")
    if what == "left|right" and arg not in ("left", "right"):
        raise ConfigError(f"fault {spec!r}: the wheel must be left or right")
    if kind == "defect":
        if arg not in DEFECTS:
            raise ConfigError(f"fault {spec!r}: unknown defect; known: {', '.join(DEFECTS)}")
    elif arg is not None and what not in (None, "left|right"):
        try:
            x = float(arg)
        except ValueError:
            raise ConfigError(f"fault {spec!r}: {arg!r} is not a number ({what})") from None
        if not math.isfinite(x) or (what.startswith("probability") and not 0 <= x <= 1):
            raise ConfigError(f"fault {spec!r}: {arg} is out of range ({what})")
        if what == "seconds" and not 0 <= x <= 10:
            raise ConfigError(f"fault {spec!r}: delay must be 0..10 s")
    return Fault(
        kind=kind,
        arg=arg,
        start=_seconds(spec, "start time @T", m["start"]) if m["start"] is not None else 0.0,
        duration=_seconds(spec, "duration +D", m["dur"]) if m["dur"] is not None else None,
    )


def _seconds(spec: str, what: str, text: str) -> float:
    """A time of a fault spec: a finite number of seconds >= 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise ConfigError(f"fault {spec!r}: the {what} must be a number of seconds >= 0, "
                          f"not {text!r} (e.g. stall:left@5+2)")
    return value
