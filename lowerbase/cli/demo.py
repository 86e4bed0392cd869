"""``lowerbase demo``: the emulator, the driver and a scenario with faults, then the report.

What a new user runs first (``make demo``): the lower computer runs as ``lowerbase emulate``
in a child process on the default transport (udp_multicast, this host only, a free port), the
driver core runs here on a python-can bus, and ``scenarios/demo.toml`` drives a loop with
realistic sensor errors, lost frames and an e-stop, in real time (~25 s) with a live status
line. ``--fast`` runs the same scenario in this process on the simulated clock (~1 s).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "demo",
        help="run the demo: emulator + driver + a scenario with faults, then the report",
        description="Start the emulated lower computer (`lowerbase emulate`) in a child "
        "process on the default transport, connect the driver core to it over python-can, "
        "run a scenario (default: the library's demo.toml: a loop with sensor errors, lost "
        "frames and an e-stop) in real time with a live status line, and write the report "
        "(plots, summary.json, junit.xml) to reports/demo-TIMESTAMP/.",
    )
    p.add_argument("--fast", action="store_true",
                   help="run in this process on the simulated clock (about a second)")
    p.add_argument("--out", metavar="DIR", help="report directory (default reports/demo-TIME)")
    p.add_argument("--scenario", metavar="FILE|NAME", default="demo",
                   help="another scenario (default: demo)")
    p.add_argument("--record", metavar="FILE",
                   help="also record the bus: .log (candump), .asc, .blf, .csv or .trc")
    p.add_argument("--foxglove", nargs="?", const="127.0.0.1:8765", metavar="HOST:PORT",
                   help="live view: watch the run in Foxglove over WebSocket (default "
                   "127.0.0.1:8765; docs/recording.md)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from lowerbase.bench.demo import StatusLine, default_bus_config, describe_bus
    from lowerbase.bench.scenario import find_scenario, load_scenario
    from lowerbase.cli.scenario import execute, print_outcomes

    scenario = load_scenario(find_scenario(args.scenario))
    out = Path(args.out) if args.out else Path("reports") / f"demo-{time.strftime('%Y%m%d-%H%M%S')}"
    err = sys.stdout  # the live status line alone goes to stderr
    if args.fast:
        mode, bus = "simulated", None
        print("lowerbase demo: the emulated lower computer and the driver core in one process, "
              "on a simulated clock", file=err)
    else:
        mode, bus = "processes", default_bus_config()
        print(f"lowerbase demo: the emulated lower computer (`lowerbase emulate`, a child "
              f"process) and the driver core (here) exchange CAN frames over "
              f"{describe_bus(bus)}", file=err)
    print(f"scenario {scenario.name} ({Path(scenario.source).name}): {scenario.description}; "
          f"{scenario.duration:g} s{'' if args.fast else ' of real time, Ctrl-C stops'}",
          file=err)
    status = StatusLine(force=not args.fast)
    result, summary = execute(scenario, out, mode=mode, record=args.record, progress=status,
                              debug=args.debug, bus_config=bus, foxglove=args.foxglove)
    print_outcomes(result, None, stream=err)
    final = summary["final"]
    err_m = final.get("odom_error_m")
    where = f"; /odom ended {err_m * 100:.1f} cm from the ground truth" if err_m is not None \
        else ""
    verdict = "interrupted" if result.interrupted else "passed" if result.passed else "FAILED"
    print(f"\ndemo {verdict}: {summary['counts']['passed']} of {len(result.outcomes)} "
          f"expectations held{where}.")
    print(f"report: {out / 'index.html'} (plots trajectory.png, velocities.png, battery.png, "
          f"status.png; summary.json, junit.xml)")
    if result.interrupted:
        return 130
    return 0 if result.passed else 1
