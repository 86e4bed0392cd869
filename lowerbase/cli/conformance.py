"""``lowerbase conformance``: the protocol conformance suite against any lower computer."""

from __future__ import annotations

import argparse
import contextlib
import sys
from typing import Any


def add_subparser(subparsers: Any) -> None:
    from lowerbase.transport import add_bus_arguments

    p = subparsers.add_parser(
        "conformance",
        help="run the protocol conformance suite against a lower computer",
        description="Check a lower computer (the emulator, or real firmware through a USB-CAN "
        "adapter or a serial port) against the catalog: every frame (present, DLC, cycle "
        "time, value ranges, counters), the request/response pairs, the safety behaviour and "
        "robustness. Takes python-can's bus flags (default: udp_multicast 239.74.163.2:43113) "
        "or --serial PORT. Exits 1 when a check fails, or when none passed (all skipped). "
        "The suite enables the chassis and turns the wheels at --speed: put a real robot on "
        "blocks, or use --no-motion.",
    )
    add_bus_arguments(p)
    p.add_argument("--junit", metavar="FILE", help="write the results as JUnit XML")
    p.add_argument("--only", action="append", default=[], metavar="PATTERN",
                   help="run only the checks whose id matches (shell pattern, comma-separated "
                   "or repeated), e.g. 'frame.Heartbeat.*,safety.*'")
    p.add_argument("--list", action="store_true", help="list the checks and exit")
    p.add_argument("--observe", type=float, default=5.0, metavar="S",
                   help="observation window for the frame checks (default 5 s)")
    p.add_argument("--cycle-tolerance", type=float, default=0.10, metavar="FRACTION",
                   help="allowed deviation of the mean cycle time (default 0.10)")
    p.add_argument("--jitter", type=float, default=0.05, metavar="S",
                   help="this host's timestamp allowance, added to the timing limits "
                   "(frame gaps, watchdog) (default 0.05 s)")
    p.add_argument("--boot-timeout", type=float, default=10.0, metavar="S",
                   help="time allowed for a reboot (default 10 s)")
    p.add_argument("--speed", type=float, default=0.1, metavar="M_S",
                   help="speed the suite commands (default 0.1 m/s)")
    p.add_argument("--no-motion", action="store_true",
                   help="skip the checks that turn the wheels")
    p.add_argument("--robot", choices=("wheeled", "legged"), default="wheeled",
                   help="legged: the quadruped's suite on its four leg buses (docs/conformance.md)")
    p.add_argument("--zero-position", action="store_true",
                   help="legged: also check the zero-position frame (re-zeroes FR hip)")
    p.set_defaults(func=run)


def _settings(args: argparse.Namespace) -> Any:
    from lowerbase.conformance import Settings
    from lowerbase.errors import ConfigError

    if not 1.0 <= args.observe <= 120.0:
        raise ConfigError("--observe must be within 1..120 s")
    if not 0.0 < args.cycle_tolerance < 1.0:
        raise ConfigError("--cycle-tolerance must be within 0..1")
    if not 0.0 <= args.jitter <= 1.0:
        raise ConfigError("--jitter must be within 0..1 s")
    if not 0.5 <= args.boot_timeout <= 120.0:
        raise ConfigError("--boot-timeout must be within 0.5..120 s")
    if not 0.02 <= args.speed <= 1.0:
        raise ConfigError("--speed must be within 0.02..1 m/s")
    return Settings(observe=args.observe, cycle_tolerance=args.cycle_tolerance,
                    jitter=args.jitter, boot_timeout=args.boot_timeout, speed=args.speed,
                    motion=not args.no_motion)


def _row(check_id: str, result: str, detail: str) -> str:
    return f"{check_id:<36} {result:<5} {detail}"


def run(args: argparse.Namespace) -> int:
    import can

    from lowerbase.conformance import (
        CheckResult,
        ConformanceClient,
        junit_xml,
        registry,
        run_suite,
        select,
    )
    from lowerbase.conformance.core import nothing_passed
    from lowerbase.errors import ConfigError, LowerbaseError
    from lowerbase.files import output_file
    from lowerbase.transport import config_from_args, describe, open_bus

    if args.junit:  # checked before the suite runs, whose results it is to hold
        output_file(args.junit, "--junit")
    if args.robot == "legged":
        from lowerbase.conformance.legged_cli import run_legged_conformance

        return run_legged_conformance(args, _row)
    checks = select(registry(), args.only)
    if not checks:
        raise ConfigError(f"no check matches --only {','.join(args.only)} (see --list)")
    if args.list:
        for c in checks:
            print(f"{c.id:<36} {c.description}")
        return 0
    settings = _settings(args)
    config = config_from_args(args)
    bus = open_bus(config)
    print(f"lowerbase conformance: {len(checks)} check{'s' if len(checks) != 1 else ''} "
          f"against {describe(config)}",
          flush=True)
    print(_row("check", "result", "detail"))
    print(_row("-" * 36, "-" * 6, "-" * 30))

    def show(result: CheckResult) -> None:
        print(_row(result.check.id, result.outcome.status.value.upper(),
                   result.outcome.detail), flush=True)

    def warn(text: str) -> None:
        print(f"lowerbase conformance: WARNING: {text}", file=sys.stderr, flush=True)

    client = ConformanceClient(bus, on_warning=warn)
    try:
        report = run_suite(client, checks, settings, on_result=show)
    finally:
        client.close()
        with contextlib.suppress(can.CanError):
            bus.shutdown()
    print(f"lowerbase conformance: {report.summary()}")
    failed = sorted(report.failed_ids())
    if failed:
        print(f"lowerbase conformance: FAILED: {', '.join(failed)}")
    if args.junit:
        junit_xml(report).write(args.junit, encoding="utf-8", xml_declaration=True)
        print(f"lowerbase conformance: JUnit XML written to {args.junit}", file=sys.stderr)
    why = nothing_passed(report, describe(config))
    if why is not None:  # all skipped: not a pass
        raise LowerbaseError(why)
    return 0 if report.ok else 1
