"""The ``lowerbase`` command: one entry point, one module per subcommand.

Each subcommand module defines ``add_subparser(subparsers)``, which registers its parser and
sets ``func`` to a ``run(args) -> int``. Modules are imported only when listed here, and their
heavy imports (rospy, pymodbus, matplotlib) happen inside ``run``, so ``lowerbase --help`` is
fast on any machine.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from lowerbase import __version__
from lowerbase.errors import LowerbaseError

#: subcommand modules under lowerbase.cli, in the order ``--help`` lists them
SUBCOMMANDS = (
    "emulate",
    "bms",
    "driver",
    "world",
    "navigation",
    "tasks",
    "trace",
    "robot",
    "scenario",
    "campaign",
    "conformance",
    "dbc",
    "decode",
    "demo",
    "record",
    "mcap",
    "ros-env",
    "ros2-env",
    "warm",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lowerbase",
        description="A virtual lower computer (chassis MCU) for differential-drive AMRs.",
    )
    parser.add_argument("--version", action="version", version=f"lowerbase {__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show tracebacks and debug logging"
    )
    subparsers = parser.add_subparsers(title="commands", dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"lowerbase.cli.{name.replace('-', '_')}")
        except ModuleNotFoundError as exc:
            if exc.name == f"lowerbase.cli.{name.replace('-', '_')}":
                continue  # subcommand not built yet
            raise
        module.add_subparser(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.debug else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # e.g. `lowerbase dbc | head`
        sys.stderr.close()
        return 0
    except (LowerbaseError, OSError) as exc:
        if args.debug:
            raise
        print(f"lowerbase {args.command}: error: {exc}", file=sys.stderr)
        return 1
