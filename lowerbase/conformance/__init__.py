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

Modules by check family: ``core`` (outcomes, checks, settings), ``catalog`` (facts derived
from the catalog), ``client``, ``context`` (what a check gets), ``frames``,
``request_response``, ``safety``, ``robustness`` and ``runner`` (the registry, the runner and
JUnit XML). Everything public is re-exported here.
"""

from __future__ import annotations

from lowerbase.conformance.catalog import (
    CONDITIONAL,
    ROW_KEYS,
    parameter_index,
    parameter_limits,
    periodic_lower_messages,
    protocol_version,
    shared_counter,
)
from lowerbase.conformance.client import (
    ConformanceClient,
    RawFrame,
)
from lowerbase.conformance.context import (
    CheckFunc,
    Context,
    MotionSender,
)
from lowerbase.conformance.core import (
    Check,
    CheckFailed,
    CheckResult,
    CheckSkipped,
    Outcome,
    Report,
    Settings,
    Status,
    failed,
    passed,
    require,
    skipped,
)
from lowerbase.conformance.frames import (
    bursts,
    counter_steps,
    cycle_stats,
    frame_checks,
    shared_cycles,
)
from lowerbase.conformance.request_response import (
    version_string,
)
from lowerbase.conformance.runner import (
    junit_xml,
    registry,
    run_check,
    run_suite,
    select,
)

__all__ = [
    "CONDITIONAL",
    "ROW_KEYS",
    "Check",
    "CheckFailed",
    "CheckFunc",
    "CheckResult",
    "CheckSkipped",
    "ConformanceClient",
    "Context",
    "MotionSender",
    "Outcome",
    "RawFrame",
    "Report",
    "Settings",
    "Status",
    "bursts",
    "counter_steps",
    "cycle_stats",
    "failed",
    "frame_checks",
    "junit_xml",
    "parameter_index",
    "parameter_limits",
    "passed",
    "periodic_lower_messages",
    "protocol_version",
    "registry",
    "require",
    "run_check",
    "run_suite",
    "select",
    "shared_counter",
    "shared_cycles",
    "skipped",
    "version_string",
]
