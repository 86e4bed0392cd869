"""``lowerbase demo``: the whole robot doing a task, or the chassis alone; then the report.

What a new user runs first (``make demo``): ``scenarios/tasks/demo.toml`` on the whole emulated
robot in this process on the simulated clock (emulator, driver core, warehouse world with
lidars and amcl, navigation, the task machine): a transport task across the warehouse past a
crate, the battery turns low, the robot charges itself; a live status line; the report has the
map with the paths, the robot_status timeline and the battery (about half a minute).

``--chassis`` runs the chassis demo instead (``scenarios/demo.toml``: a loop with sensor
errors, lost frames and an e-stop): the lower computer as ``lowerbase emulate`` in a child
process on the default transport, the driver core here, in real time (~25 s); with ``--fast``
in this process on the simulated clock (~1 s).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

TASK_DEMO, CHASSIS_DEMO = "tasks/demo", "demo"


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "demo",
        help="run the demo: the whole robot does a transport task and charges, then the report",
        description="Run the library's task demo (scenarios/tasks/demo.toml) on the whole "
        "emulated robot on the simulated clock: a transport task across the warehouse past "
        "a crate, a low battery and a charge, with a live status line; the report (map with "
        "the paths, robot_status timeline, battery; summary.json, junit.xml) goes to "
        "reports/demo-TIMESTAMP/. --chassis: the chassis demo (emulator in a child process, "
        "driver here, a loop with faults, in real time).",
    )
    p.add_argument("--chassis", action="store_true",
                   help="the chassis demo: `lowerbase emulate` in a child process + the driver "
                   "core, a loop with sensor errors, lost frames and an e-stop (~25 s)")
    p.add_argument("--fast", action="store_true",
                   help="with --chassis: run in this process on the simulated clock (~1 s)")
    p.add_argument("--out", metavar="DIR", help="report directory (default reports/demo-TIME)")
    p.add_argument("--scenario", metavar="FILE|NAME",
                   help="another scenario: a task scenario runs like the task demo, a chassis "
                   "one like --chassis (default: tasks/demo, or demo with --chassis)")
    p.add_argument("--record", metavar="FILE",
                   help="chassis demo: also record the bus (.log, .asc, .blf, .csv or .trc)")
    p.add_argument("--no-mcap", dest="mcap", action="store_false",
                   help="do not write run.mcap into the report (the task demo's recording "
                   "takes about 3 x the run's CPU time: docs/recording.md)")
    p.add_argument("--foxglove", nargs="?", const="127.0.0.1:8765", metavar="HOST:PORT",
                   help="watch the run in Foxglove over WebSocket (default 127.0.0.1:8765; "
                   "docs/recording.md); the task demo streams as fast as it runs")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from lowerbase.cli.args import check_outputs
    from lowerbase.errors import ConfigError
    from lowerbase.scenarios.catalog import find_scenario, load_any_scenario
    from lowerbase.scenarios.tasks import TasksScenario

    name = args.scenario or (CHASSIS_DEMO if args.chassis else TASK_DEMO)
    scenario = load_any_scenario(find_scenario(name))
    out = Path(args.out) if args.out else Path("reports") / f"demo-{time.strftime('%Y%m%d-%H%M%S')}"
    if isinstance(scenario, TasksScenario):
        given = [flag for flag, on in (("--chassis", args.chassis), ("--fast", args.fast),
                                       ("--record", args.record)) if on]
        if given:
            raise ConfigError(f"{given[0]} is for a chassis scenario; the task demo "
                              f"({scenario.name}) always runs on the simulated clock: drop it")
        if args.foxglove is not None:  # a bad address: one line before anything runs
            from lowerbase.recording.live import parse_address

            parse_address(args.foxglove)
        check_outputs(args, out)
        return run_tasks(scenario, out, debug=args.debug, foxglove=args.foxglove,
                         mcap=args.mcap)
    check_outputs(args, out)
    return run_chassis(args, scenario, out)


def run_tasks(scenario: Any, out: Path, *, debug: bool = False,
              foxglove: str | None = None, mcap: bool = True) -> int:
    from lowerbase.reports.tasks import exit_code, print_outcomes, run_and_report
    from lowerbase.scenarios.demo import TaskStatusLine

    print("lowerbase demo: the whole robot in this process on the simulated clock: the "
          "emulated lower computer, the driver core, the world (map, lidars, amcl), "
          "navigation and the task machine (exec_task, robot_status)")
    print(f"scenario {scenario.name} ({Path(scenario.source).name}): {scenario.description}; "
          f"{scenario.duration:g} s simulated, Ctrl-C stops")
    from lowerbase.jit import uncached

    if uncached():
        print("compiling the numba kernels first (not cached yet: a few minutes, once; "
              "`make env` or `lowerbase warm` does it ahead)")
    sys.stdout.flush()
    result, summary = run_and_report(scenario, out, TaskStatusLine(force=True, period=10.0),
                                     debug=debug, mcap=out / "run.mcap" if mcap else None,
                                     foxglove=foxglove)
    if summary is None:
        return 130
    print_outcomes(result)
    b = summary["battery"]
    durations = [f"task {e.task_id} took {why.removeprefix('took ')}"
                 for e, _, why in result.outcomes if e.kind == "task_duration"]
    verdict = "interrupted" if result.interrupted else "passed" if result.passed else "FAILED"
    print(f"\ndemo {verdict}: {summary['counts']['passed']} of {len(result.outcomes)} "
          f"expectations held; {', '.join([*durations, ''])}driven {summary['driven_m']:.1f} m, "
          f"SOC {b['soc_start']:.2f} -> {b['soc_min']:.2f} -> {b['soc_end']:.2f} %.")
    print(f"report: {out / 'index.html'} (map.png, timeline.png, battery.png; summary.json, "
          f"junit.xml{'; run.mcap for Foxglove' if mcap else ''})")
    return exit_code(result)


def run_chassis(args: argparse.Namespace, scenario: Any, out: Path) -> int:
    from lowerbase.cli.scenario import execute, print_outcomes
    from lowerbase.errors import ConfigError
    from lowerbase.scenarios.demo import StatusLine, default_bus_config, describe_bus
    from lowerbase.scenarios.wheeled import Scenario

    if not isinstance(scenario, Scenario):
        raise ConfigError(f"scenario {scenario.name}: the demo runs task and chassis "
                          f"scenarios; run this one with `lowerbase scenario run`")
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
                              debug=args.debug, bus_config=bus, foxglove=args.foxglove,
                              mcap=args.mcap)
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
