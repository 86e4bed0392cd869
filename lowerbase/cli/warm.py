"""``lowerbase warm``: compile the numba kernels into their cache now (``make env`` runs it), so
the first demo or run is as fast as the next; with ``--check``, only say which are missing."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
import time
from typing import Any

#: simulated seconds of the task demo that touch every kernel (the lower computer's lean
#: loop, the IMU, the EKF, the lidars' casts, amcl, the costmaps and the planner)
WARM_SECONDS = 20.0
#: then simulated seconds of the legged robot standing up (its period's kernels and its
#: driver's batch decode)
LEGGED_WARM_SECONDS = 0.5


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "warm",
        help="compile the numba kernels into their cache now (make env does), so the first "
        "run is as fast as the next",
        description="Run a short stretch of the task demo, then half a second of the legged "
        "robot, on the simulated clock so that every numba kernel is compiled and cached "
        "(minutes on the first run, seconds after). "
        "`make env` runs it; run it yourself after changing a kernel's package.",
    )
    p.add_argument("--check", action="store_true",
                   help="only list the kernel modules not compiled yet (exit 1 if any)")
    p.set_defaults(func=run)


def _legged() -> None:
    from lowerbase.protocol.legged import LocomotionState
    from lowerbase.simloop.legged import LeggedSimLoop

    loop = LeggedSimLoop()
    try:
        loop.set_goal(LocomotionState.STANDING_MODE)
        loop.run(LEGGED_WARM_SECONDS)
    finally:
        loop.close()


def run(args: argparse.Namespace) -> int:
    from lowerbase.jit import KERNEL_MODULES, uncached

    missing = uncached()
    if args.check:
        for module in missing:
            print(f"lowerbase warm: {module}: not compiled yet")
        print(f"lowerbase warm: {len(KERNEL_MODULES) - len(missing)} of {len(KERNEL_MODULES)} "
              "kernel modules compiled and cached"
              + ("" if not missing else "; `lowerbase warm` compiles the rest"))
        return 1 if missing else 0
    from lowerbase.scenarios.catalog import find_scenario, load_any_scenario
    from lowerbase.scenarios.tasks_run import run_tasks_scenario

    t0 = time.monotonic()
    if missing:
        print(f"lowerbase warm: compiling the numba kernels ({len(missing)} of "
              f"{len(KERNEL_MODULES)} modules not cached yet: a few minutes) on "
              f"{WARM_SECONDS:g} s of the task demo", flush=True)
    else:
        print(f"lowerbase warm: all {len(KERNEL_MODULES)} kernel modules cached; checking "
              f"them on {WARM_SECONDS:g} s of the task demo", flush=True)
    from lowerbase.scenarios.tasks import TasksScenario

    scenario = load_any_scenario(find_scenario("tasks/demo"))
    assert isinstance(scenario, TasksScenario)
    quiet = logging.getLogger("lowerbase")
    level = quiet.level
    quiet.setLevel(logging.WARNING)  # the run's own log lines are not this command's
    try:
        run_tasks_scenario(dataclasses.replace(scenario, duration=WARM_SECONDS))
        _legged()
    finally:
        quiet.setLevel(level)
    left = uncached()
    if left:
        print(f"lowerbase warm: still not cached: {', '.join(left)} (is the package's "
              "__pycache__ or NUMBA_CACHE_DIR writable?)", file=sys.stderr)
        return 1
    print(f"lowerbase warm: all {len(KERNEL_MODULES)} kernel modules compiled and cached in "
          f"{time.monotonic() - t0:.0f} s", flush=True)
    return 0
