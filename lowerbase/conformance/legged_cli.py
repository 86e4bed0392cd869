"""``lowerbase conformance --robot legged``: the legged suite on the four leg buses (the
options and the output are the wheeled command's; lowerbase/cli/conformance.py dispatches)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from lowerbase.conformance.core import CheckResult, nothing_passed
from lowerbase.errors import ConfigError, LowerbaseError


def run_legged_conformance(args: argparse.Namespace, row: Callable[[str, str, str], str]) -> int:
    from lowerbase.conformance.legged_context import LeggedSettings
    from lowerbase.conformance.legged_link import BusesLink
    from lowerbase.conformance.legged_runner import legged_registry, run_legged_suite
    from lowerbase.conformance.runner import junit_xml, select
    from lowerbase.legged.runner import close_buses, leg_bus_configs
    from lowerbase.transport import config_from_args, describe, open_bus

    if getattr(args, "serial", None):
        raise ConfigError("--robot legged runs on four CAN buses, not --serial; drop it")
    checks = select(legged_registry(), args.only)
    if not checks:
        raise ConfigError(f"no check matches --only {','.join(args.only)} (see --list)")
    if args.list:
        for c in checks:
            print(f"{c.id:<36} {c.description}")
        return 0
    if not 3.0 <= args.observe <= 120.0:
        raise ConfigError("--observe must be within 3..120 s for the legged robot")
    if not 0.0 < args.cycle_tolerance < 1.0:
        raise ConfigError("--cycle-tolerance must be within 0..1")
    if not 0.0 <= args.jitter <= 1.0:
        raise ConfigError("--jitter must be within 0..1 s")
    if not 0.02 <= args.speed <= 1.0:
        raise ConfigError("--speed must be within 0.02..1 m/s")
    settings = LeggedSettings(observe=args.observe, cycle_tolerance=args.cycle_tolerance,
                              jitter=args.jitter, speed=args.speed, motion=not args.no_motion,
                              zero_position=args.zero_position)
    config = config_from_args(args)
    configs = leg_bus_configs(config)
    buses = []
    try:
        for cfg in configs:
            buses.append(open_bus(cfg))
        print(f"lowerbase conformance: {len(checks)} legged check"
              f"{'s' if len(checks) != 1 else ''} against the four leg buses of "
              f"{describe(config)}", flush=True)
        print(row("check", "result", "detail"))
        print(row("-" * 36, "-" * 6, "-" * 30))

        def show(result: CheckResult) -> None:
            print(row(result.check.id, result.outcome.status.value.upper(),
                      result.outcome.detail), flush=True)

        link = BusesLink(buses)
        try:
            report = run_legged_suite(link, checks, settings, on_result=show)
        finally:
            link.close()
    finally:
        close_buses(buses)
    print(f"lowerbase conformance: {report.summary()}")
    failed = sorted(report.failed_ids())
    if failed:
        print(f"lowerbase conformance: FAILED: {', '.join(failed)}")
    if args.junit:
        junit_xml(report, "lowerbase.conformance.legged").write(
            args.junit, encoding="utf-8", xml_declaration=True)
        print(f"lowerbase conformance: JUnit XML written to {args.junit}", file=sys.stderr)
    why = nothing_passed(report, f"the four leg buses of {describe(config)}")
    if why is not None:  # all skipped: not a pass
        raise LowerbaseError(why)
    return 0 if report.ok else 1
