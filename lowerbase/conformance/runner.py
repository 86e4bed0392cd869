"""The registry of checks in run order, selection, the runner and JUnit XML."""

from __future__ import annotations

import fnmatch
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable, Sequence

import can

from lowerbase.conformance.client import ConformanceClient
from lowerbase.conformance.context import Context
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
    skipped,
)
from lowerbase.conformance.frames import frame_checks
from lowerbase.conformance.physics import (
    check_gravity,
    check_gyro,
    check_motion_state,
    check_odometer,
    check_wheel_count,
    check_wheel_velocity,
)
from lowerbase.conformance.request_response import (
    WRITE_PARAMETER,
    check_led,
    check_link,
    check_param_out_of_range,
    check_param_read,
    check_param_unknown,
    check_param_write,
    check_version_all,
    check_version_field,
)
from lowerbase.conformance.robustness import (
    check_bad_dlc,
    check_extended_ids,
    check_out_of_range,
    check_unknown_ids,
)
from lowerbase.conformance.safety import (
    check_enable,
    check_estop,
    check_reboot,
    check_standby,
    check_standby_after_boot,
    check_standby_ignores_motion,
    check_watchdog,
)
from lowerbase.errors import ProtocolError
from lowerbase.protocol.codec import Codec, default_codec

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
        Check("physics.gravity", "at rest the accelerometer reads gravity on +z",
              check_gravity),
        Check("physics.wheel_velocity", "wheel Velocity follows the commanded motion",
              check_wheel_velocity),
        Check("physics.wheel_count", "Count deltas agree with the integrated Velocity",
              check_wheel_count),
        Check("physics.motion_state", "MotionState agrees with the wheel kinematics",
              check_motion_state),
        Check("physics.gyro", "the integrated gyro z agrees with MotionState (or is 0 on "
              "blocks)", check_gyro),
        Check("physics.odometer", "Odometer Distance grows at the centre speed of the wheel "
              "Counts", check_odometer),
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


def run_in_order(checks: Sequence[Check], ctx: Context,
                 on_result: Callable[[CheckResult], None] | None) -> list[CheckResult]:
    """Each check in turn, timed (while no lower computer answers, link.heartbeat alone runs:
    the others are skipped); each result to ``on_result`` as it comes."""
    results: list[CheckResult] = []
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
    return results


def run_suite(
    client: ConformanceClient, checks: Sequence[Check], settings: Settings | None = None,
    on_result: Callable[[CheckResult], None] | None = None,
) -> Report:
    """Run ``checks`` in order against the lower computer behind ``client``."""
    settings = settings or Settings()
    start = time.monotonic()
    ctx = Context(client, settings)
    try:
        ctx.connect()
        results = run_in_order(checks, ctx, on_result)
    finally:
        problems = ctx.finish()
    if problems:
        check = Check("cleanup", "parameters restored, standby", lambda _: failed(""))
        results.append(CheckResult(check, failed("; ".join(problems)), 0.0))
        if on_result is not None:
            on_result(results[-1])
    return Report(tuple(results), time.monotonic() - start, linked=ctx.linked)


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
