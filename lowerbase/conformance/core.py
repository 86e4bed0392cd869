"""Outcomes, checks, reports and the settings of a run."""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

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




@dataclass(frozen=True)
class Check:
    id: str  #: dotted, e.g. ``frame.WheelFeedback.cycle``; the first part is the group
    description: str
    func: Callable[[Any], Outcome]  #: a context.CheckFunc (or a legged one)

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
    linked: bool = True  #: a lower computer was heard on the bus

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


def nothing_passed(report: Report, bus: str) -> str | None:
    """Why a run in which no check failed is still a failure: none passed (None: some did).
    ``bus``: where the suite listened, for the user to check."""
    if report.count(Status.PASS) or not report.ok:
        return None
    if not report.linked:
        return (f"nothing passed: no frame from a lower computer on {bus}: is it running, "
                "and are the bus flags (-i/-c/--bus-kwargs port=..., --serial) its own?")
    return ("nothing passed: every check was skipped (each row says why); select checks "
            "that apply, e.g. without --no-motion or with another --only")


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
    speed: float = 0.1  #: [m/s] the MotionCommand the suite sends (robot on blocks)
    motion: bool = True  #: False skips the checks that turn the wheels
