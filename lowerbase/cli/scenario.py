"""``lowerbase scenario``: run, check, list and replay scenarios (docs/scenarios.md)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from lowerbase.cli.args import check_outputs

MODES = ("simulated", "realtime", "processes")


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "scenario",
        help="run a scenario (faults, expectations) and write its report",
        description="Scenarios describe a run of the chassis in TOML: the profile, the "
        "initial state, a timeline of actions and faults, and expectations. See "
        "docs/scenarios.md; `lowerbase scenario list` shows the library.",
    )
    sub = p.add_subparsers(title="actions", dest="scenario_command", metavar="ACTION")
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])

    run = sub.add_parser(
        "run", help="run a scenario and write its report (exit 1 when an expectation fails)",
        description="Run a scenario file (or a library scenario by name) and write the "
        "report: plots, summary.json, junit.xml, trace.csv and index.html.")
    run.add_argument("scenario", metavar="FILE|NAME")
    run.add_argument("--out", metavar="DIR",
                     help="report directory (default: reports/NAME-TIMESTAMP)")
    timing = run.add_mutually_exclusive_group()
    timing.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                        help="pace the simulation to the wall clock (same model, same result)")
    timing.add_argument("--processes", dest="mode", action="store_const", const="processes",
                        help="run the lower computer as `lowerbase emulate` in a child "
                        "process on the default transport, the driver here (real time)")
    run.add_argument("--record", metavar="FILE",
                     help="record every frame: .log (candump), .asc, .blf, .csv or .trc")
    mcap = run.add_mutually_exclusive_group()
    mcap.add_argument("--mcap", metavar="FILE.mcap",
                      help="write the run's ROS1 topics, ground truth and CAN frames here "
                      "(default: run.mcap in the report directory; docs/recording.md)")
    mcap.add_argument("--no-mcap", dest="mcap", action="store_false",
                      help="do not write the MCAP recording")
    run.add_argument("--foxglove", nargs="?", const="127.0.0.1:8765", metavar="HOST:PORT",
                     help="live view: serve the MCAP's channels to Foxglove over WebSocket "
                     "(default 127.0.0.1:8765); use with --realtime or --processes to watch "
                     "at the robot's pace (docs/recording.md)")
    run.add_argument("--progress", action="store_true",
                     help="show the progress bar even when stderr is not a terminal")
    run.add_argument("--status", action="store_true",
                     help="show a live status line (pose, speed, SOC, StatusCode) instead")
    run.set_defaults(func=run_command, mode="simulated", mcap=None)

    check = sub.add_parser("check", help="validate scenario files without running them")
    check.add_argument("scenarios", nargs="+", metavar="FILE|NAME")
    check.set_defaults(func=check_command)

    lst = sub.add_parser("list", help="list the library scenarios")
    lst.set_defaults(func=list_command)

    replay = sub.add_parser(
        "replay", help="replay a recording through the driver core: /odom_raw and /odom",
        description="Feed the lower computer's frames of a recording (.log, .asc, .blf, ...) "
        "into the ROS-free driver core and plot the odometry it computes.")
    replay.add_argument("recording", metavar="FILE")
    replay.add_argument("--out", metavar="DIR",
                        help="report directory (default: reports/replay-NAME-TIMESTAMP)")
    replay.add_argument("--pose", nargs=3, type=float, metavar=("X", "Y", "YAW"),
                        default=(0.0, 0.0, 0.0), help="initial pose of the run [m m rad]")
    replay.set_defaults(func=replay_command)


def default_out(name: str) -> Path:
    return Path("reports") / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}"


def execute(scenario: Any, out: Path, *, mode: str = "simulated", record: str | None = None,
            progress: Any = None, debug: bool = False,
            bus_config: dict[str, Any] | None = None,
            mcap: str | Path | bool | None = True,
            foxglove: str | None = None) -> tuple[Any, dict[str, Any]]:
    """Run ``scenario`` in ``mode``, optionally recording, and write the report into ``out``.

    Log records of the run go to ``out/run.log`` (also to stderr with ``debug``). ``mcap``:
    see :func:`mcap_path` (the driver's topics, the truth and the frames; docs/recording.md).
    ``foxglove``: HOST:PORT of a live Foxglove WebSocket server with the same channels (on the
    simulated clock it streams as fast as the run goes).
    """
    from lowerbase.recording.world import attach_world
    from lowerbase.reports.outputs import log_to_file, mcap_path
    from lowerbase.reports.wheeled import write_report
    from lowerbase.scenarios.replay import BusRecorder, check_recording_path
    from lowerbase.scenarios.runner import SimHarness, run_scenario

    if mode == "processes":
        from lowerbase.scenarios.demo import check_over_bus

        check_over_bus(scenario)  # before anything is started or written
    mcap_file = mcap_path(out, mcap)
    live = None
    if foxglove is not None:  # a bad address or a busy port stops here, before any file
        from lowerbase.recording.live import start_live

        live = start_live(foxglove, announce=lambda line: print(line, file=sys.stderr))
    try:
        recorder = BusRecorder(check_recording_path(record)) if record else None
        mcap_rec: Any = None
        if mcap_file is not None:
            from lowerbase.recording.mcap_writer import McapRecorder

            mcap_rec = McapRecorder(mcap_file, extra=(live,) if live is not None else ())
        elif live is not None:
            from lowerbase.recording.publisher import RunPublisher

            mcap_rec = RunPublisher([live])
    except BaseException:
        if live is not None:
            live.close()
        raise
    taps = [t for t in (recorder, mcap_rec) if t is not None]

    def tap(t: float, direction: str, frame_id: int, data: bytes) -> None:
        for each in taps:
            each(t, direction, frame_id, data)

    def attach(harness: Any) -> None:
        if mcap_rec is not None:
            mcap_rec.attach(harness.driver, harness.now, harness.truth)
            if getattr(harness, "world", None) is not None:  # /map, /scan, /amcl_pose, ...
                attach_world(mcap_rec, harness.world)

    try:
        with log_to_file(out / "run.log", echo=debug):
            if mode == "processes":
                from lowerbase.scenarios.demo import run_over_bus

                result = run_over_bus(scenario, out, tap=tap if taps else None,
                                      progress=progress, bus_config=bus_config,
                                      on_start=attach)
            else:
                realtime = mode == "realtime"
                harness = SimHarness(scenario, tap=tap if taps else None, realtime=realtime)
                attach(harness)
                try:
                    result = run_scenario(scenario, harness, progress=progress,
                                          mode="realtime" if realtime else "simulated")
                finally:
                    harness.close()
    finally:
        if recorder is not None:
            recorder.close()
        if mcap_rec is not None:
            mcap_rec.close()
        if progress is not None:
            progress.done()
    summary = write_report(result, out, recording=recorder.path if recorder else None)
    return result, summary


def print_outcomes(result: Any, out: Path | None, *, stream: Any = None) -> None:
    """One line per expectation, the verdict, and (with ``out``) where the report is."""
    stream = stream or sys.stdout
    for exp, outcome in result.outcomes:
        print(f"  {outcome.status.upper():<7} {exp.title()}: {outcome.detail}", file=stream)
    counts = {k: sum(1 for _, o in result.outcomes if o.status == k)
              for k in ("passed", "failed", "skipped")}
    verdict = "INTERRUPTED" if result.interrupted else "PASSED" if result.passed else "FAILED"
    extra = f", {counts['skipped']} skipped" if counts["skipped"] else ""
    print(f"scenario {result.scenario.name}: {verdict} ({counts['passed']} passed, "
          f"{counts['failed']} failed{extra}); {result.trace.end:.1f} s {result.mode} in "
          f"{result.wall_time:.1f} s", file=stream)
    lag = getattr(result, "lag", None)
    if lag is not None and lag.lagged:
        print(f"  note: {lag.describe()}", file=stream)
    if out is not None:
        print(f"report: {out / 'index.html'} (plots, summary.json, junit.xml)", file=stream)


def run_command(args: argparse.Namespace) -> int:
    from lowerbase.scenarios.catalog import find_scenario, load_any_scenario

    if args.foxglove is not None:  # a bad address is refused before anything is said
        from lowerbase.recording.live import parse_address

        parse_address(args.foxglove)
    scenario = load_any_scenario(find_scenario(args.scenario))
    out = Path(args.out) if args.out else default_out(scenario.name)
    check_outputs(args, out)
    return run_loaded(args, scenario, out)


def run_loaded(args: argparse.Namespace, scenario: Any, out: Path) -> int:
    """``lowerbase scenario run`` of a scenario already built (``lowerbase campaign replay``
    builds one run's); its report goes to ``out``."""
    from lowerbase.reports.outputs import mcap_path
    from lowerbase.scenarios.demo import ProgressBar, StatusLine
    from lowerbase.scenarios.legged import LeggedScenario
    from lowerbase.scenarios.tasks import TasksScenario

    if isinstance(scenario, LeggedScenario):  # robot = "legged": its own runner and report
        from lowerbase.reports.legged import run_command as run_legged

        return run_legged(args, scenario, out)
    if isinstance(scenario, TasksScenario):  # a [tasks] table: TaskSim, its own report
        from lowerbase.reports.tasks import run_command as run_tasks

        return run_tasks(args, scenario, out)
    progress: Any
    if args.status or args.mode != "simulated":
        progress = StatusLine(force=args.status or args.progress)
    else:
        progress = ProgressBar(scenario.duration, force=args.progress)
    print(f"scenario {scenario.name}: {scenario.description or scenario.source} "
          f"({scenario.duration:g} s, {args.mode})", file=sys.stderr)
    result, _ = execute(scenario, out, mode=args.mode, record=args.record, progress=progress,
                        debug=args.debug, mcap=True if args.mcap is None else args.mcap,
                        foxglove=args.foxglove)
    print_outcomes(result, out)
    if args.record:
        print(f"recording: {args.record}")
    written = mcap_path(out, True if args.mcap is None else args.mcap)
    if written is not None:
        print(f"mcap: {written} (Foxglove, PlotJuggler; `lowerbase mcap to-bag` for rosbag)")
    if result.interrupted:
        return 130
    return 0 if result.passed else 1


def check_command(args: argparse.Namespace) -> int:
    from lowerbase.scenarios.catalog import find_scenario, load_any_scenario

    for name in args.scenarios:
        s = load_any_scenario(find_scenario(name))
        print(f"{s.source}: ok ({len(s.timeline)} timeline item(s), "
              f"{len(s.expectations)} expectation(s), {s.duration:g} s)")
    return 0


def list_command(args: argparse.Namespace) -> int:
    from lowerbase.scenarios.catalog import library, load_any_scenario

    for name, path in library("all").items():
        s = load_any_scenario(path)
        print(f"{name:<20} {s.duration:5.0f} s  {s.description}")
    return 0


def replay_command(args: argparse.Namespace) -> int:
    import json

    from lowerbase.reports.wheeled import _pyplot, plot_status, plot_trajectory, plot_velocities
    from lowerbase.scenarios.replay import check_recording_path, replay

    path = check_recording_path(args.recording, must_exist=True)
    out = Path(args.out) if args.out else default_out(f"replay-{path.stem}")
    check_outputs(args, out)
    result = replay(path, pose=tuple(args.pose))
    out.mkdir(parents=True, exist_ok=True)
    plt = _pyplot()
    title = f"replay of {path.name}"
    for name, fn in (("trajectory.png", plot_trajectory), ("velocities.png", plot_velocities),
                     ("status.png", plot_status)):
        fig = fn(result.trace, [], title)
        fig.savefig(out / name, dpi=100)
        plt.close(fig)
    odo = result.driver.odometry
    final: dict[str, dict[str, float] | None] = {
        "odom_raw": None if odo is None else {"x": odo.x, "y": odo.y, "yaw": odo.yaw},
        "odom": dict(zip(("x", "y", "yaw"), result.driver.ekf.pose, strict=True)),
    }
    summary = {"recording": str(path), "frames": result.frames,
               "duration_s": result.trace.end, "reboots": result.driver.reboots,
               "final": final, "files": ["trajectory.png", "velocities.png", "status.png"]}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(f"replayed {result.frames} frames ({result.trace.end:.1f} s) of {path}")
    r, e = final["odom_raw"], final["odom"]
    if r is not None and e is not None:
        print(f"final /odom_raw x {r['x']:+.3f} y {r['y']:+.3f} yaw {r['yaw']:+.3f}; "
              f"/odom x {e['x']:+.3f} y {e['y']:+.3f} yaw {e['yaw']:+.3f}")
    else:
        print("the driver never got the parameters it needs: no odometry in this recording")
    print(f"report: {out}/ (trajectory.png, velocities.png, status.png, summary.json)")
    return 0
