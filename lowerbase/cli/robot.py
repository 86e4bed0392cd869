"""``lowerbase robot``: the whole virtual robot in one command.

On the ROS master in ROS_MASTER_URI (or a ``rosmaster --core`` of its own when none answers
there), in processes of their own: the world (map, lidars, camera, localization), the emulated
lower computer on that map, driver_base on the bus, and the layers above it (navigation,
tasks). One status line shows the parts; Ctrl-C stops them all, the top ones first. Each
part's output goes to a log file of its own (``--log-dir``).
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from lowerbase.cli.args import positive_seconds, seed
from lowerbase.errors import ConfigError, LowerbaseError
from lowerbase.files import output_dir, output_file
from lowerbase.text import clip


def add_subparser(subparsers: Any) -> None:
    from lowerbase.robot.plan import UPPER
    from lowerbase.world.maps import DEFAULT_MAP

    p = subparsers.add_parser(
        "robot", help="start the whole virtual robot (lower computer, driver, world, "
        "navigation, tasks) on a ROS master",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None)
    p.add_argument("--map", default=DEFAULT_MAP, metavar="NAME|FILE",
                   help=f"a packaged map name or a map_server YAML file (default {DEFAULT_MAP})")
    p.add_argument("--without", action="append", default=[], choices=UPPER, metavar="PART",
                   help=f"leave out an upper layer ({', '.join(UPPER)}); repeatable")
    p.add_argument("--log-dir", metavar="DIR",
                   help="where each part's output goes (default: a new directory under /tmp)")
    p.add_argument("--foxglove", nargs="?", const="127.0.0.1:8765", metavar="HOST:PORT",
                   help="serve the robot live to Foxglove: the ROS topics and CAN frames "
                   "--mcap records (default 127.0.0.1:8765)")
    p.add_argument("--truth", metavar="FILE",
                   help="the emulator writes its ground truth there (t,x,y,yaw,v,w CSV every "
                   "20 ms, in the emulator's frame: the map pose is the map's start composed "
                   "with it; lowerbase emulate --truth)")
    p.add_argument("--mcap", metavar="FILE.mcap",
                   help="record the robot: its ROS topics and the bus's CAN frames into one "
                   "MCAP file, finished at Ctrl-C (docs/recording.md)")
    p.add_argument("--ground-truth", action="store_true",
                   help="localization is the emulator's true pose instead of amcl's estimate "
                   "(lowerbase world --ground-truth, as fake_localization)")
    p.add_argument("--soc", type=_soc_percent, metavar="PERCENT",
                   help="the battery's charge at start (lowerbase emulate --soc; default "
                   "the emulator's 80 %%)")
    p.add_argument("--duration", type=positive_seconds, metavar="S",
                   help="stop after S seconds of wall time (default: until Ctrl-C)")
    p.add_argument("--sim-time", action="store_true",
                   help="lockstep simulated time: every part in one process on one clock, "
                   "/use_sim_time true and /clock from it; the same result on a busy host as "
                   "on an idle one (docs/robot.md)")
    p.add_argument("--speed", type=_speed_factor, metavar="K|max",
                   help=f"with --sim-time: at most K simulated seconds per wall second "
                   f"(default {DEFAULT_SPEED:g}; max: as fast as the host allows; the status "
                   "line shows what it achieves)")
    p.add_argument("--paused", action="store_true",
                   help="with --sim-time: start paused; time moves only on /lowerbase/step "
                   "(lowerbase_sim_msgs/Step), for reproducible tests of your nodes")
    p.add_argument("--respawn", action="store_true",
                   help="start navigation and tasks again when they end (as roslaunch's "
                   "respawn), so your software can be tested against a crashing part; "
                   "without it one part ending ends the robot")
    p.add_argument("--robot", choices=("wheeled", "legged"), default="wheeled",
                   help="with --sim-time: the wheeled AMR (default) or seed 003's legged robot "
                   "(its lower computer and legged driver in lockstep; docs/legged.md)")
    p.add_argument("--ros2", action="store_true",
                   help="the lockstep robot (as --sim-time) with its interface on ROS 2 "
                   "(rclpy, Fast DDS; nav2's navigate_to_pose beside move_base); run from "
                   ".venv-ros2 after "
                   "`make ros2`, docs/ros2.md")
    p.add_argument("ros_args", nargs="*", metavar="_NAME:=VALUE",
                   help="with --ros2: a ROS 2 parameter of /lowerbase_robot, e.g. "
                   "_move_base/recovery_behaviors:=[clear_costmap,rotate_recovery] (on ROS 1 "
                   "the parameter server's /move_base/recovery_behaviors)")
    p.add_argument("--camera", action="store_true",
                   help="with --sim-time: the depth camera too (/camera_1/..., ~50 ms of CPU a "
                   "frame at 15 Hz of simulated time; the real-time robot's world always has "
                   "it)")
    p.add_argument("--seed", type=seed, default=0, metavar="S",
                   help="with --sim-time: the seed of the localization's random numbers "
                   "(default 0)")
    p.set_defaults(func=run)


#: --sim-time's default speed: real time, as a simulator shown to a person (CI: max)
DEFAULT_SPEED = 1.0
#: --speed max
MAX_SPEED = float("inf")


def _speed_factor(text: str) -> float:
    from lowerbase.cli.emulate import _speed_factor as emulate_speed

    if text.strip().lower() == "max":
        return MAX_SPEED
    return emulate_speed(text)


def _soc_percent(text: str) -> float:
    """--soc: a charge in 0..100 %."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0.0 <= value <= 100.0:
        raise argparse.ArgumentTypeError(f"{text}: the charge must be within 0..100 %")
    return value


def _check_listen(address: str) -> None:
    """A bad HOST:PORT or a port in use is one ConfigError line before anything starts (the
    recorder child listens there later)."""
    import socket

    from lowerbase.recording.live import parse_address

    host, port = parse_address(address)
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        with socket.socket(infos[0][0], socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server does
            s.bind(infos[0][4])
    except OSError as exc:
        raise ConfigError(f"--foxglove {host}:{port}: cannot listen ({exc.strerror or exc}); "
                          f"give another port, e.g. --foxglove {host}:{port + 1}") from None


def _on_ready(child: Any) -> None:
    print(f"lowerbase robot: {child.spec.name} up", flush=True)
    if child.spec.name == "recorder":
        import re

        url = re.search(r"ws://\S+", child.log_path.read_text(errors="replace"))
        if url:
            print(f"lowerbase robot: live view: Foxglove -> Open connection -> Foxglove "
                  f"WebSocket {url.group(0)} (layout: lowerbase/recording/"
                  f"foxglove-layout.json)", flush=True)


def _on_respawn(old: Any, new: Any) -> None:
    """An upper part ended and was started again (--respawn): its crash, in one line."""
    print(f"lowerbase robot: warning: {old.spec.name} ended (exit code {old.poll()}): "
          f"{clip(' | '.join(old.final_lines or []) or 'no output', 600)}; started again "
          f"(respawn {new.respawns}; its log goes on in {new.log_path})", file=sys.stderr,
          flush=True)


def _report_down(report: Any, sup: Any, child: Any) -> None:
    """A part that ended (to be respawned, or ending the run): on robot_status first, while
    the others still run; one line on how that went."""
    def tasks_alive() -> bool:
        return any(c.spec.name == "tasks" and c.poll() is None for c in sup.children)

    try:
        shown = child.spec.name != "tasks" and report.down(child, tasks_alive)
    except (OSError, LowerbaseError) as exc:
        print(f"lowerbase robot: warning: cannot tell robot_status that {child.spec.name} "
              f"ended ({exc})", file=sys.stderr, flush=True)
        return
    if shown:
        print(f"lowerbase robot: robot_status reports that {child.spec.name} ended",
              file=sys.stderr, flush=True)


def _on_lost(child: Any) -> None:
    """A part the robot goes on without (the recorder) ended: one line saying what to do."""
    what = ""
    if child.spec.name == "recorder":
        what = ("; the robot goes on without a recording (an unfinished .mcap: "
                "lowerbase mcap recover IN.mcap OUT.mcap)")
    print(f"lowerbase robot: warning: {child.spec.name} ended (exit code {child.poll()}): "
          f"{child.last_line or 'no output'}; see {child.log_path}{what}", file=sys.stderr,
          flush=True)


def _status(sup: Any, started: float, master: str, watch: Any = None) -> str:
    parts = " ".join(f"{c.spec.name} {'up' if c.ready else 'starting'}" for c in sup.children)
    sim = "" if watch is None else f" | {watch.status()}"
    return f"lowerbase robot: {parts} | master {master} | {time.monotonic() - started:.0f} s{sim}"


def _use_sim_time(uri: str, sim: bool) -> Any:
    """Set /use_sim_time for this run (true with --sim-time; false when a previous run left it
    true); returns what restores the master's previous value."""
    from lowerbase.robot.master import delete_param, get_param, set_param

    previous = get_param(uri, "/use_sim_time")
    if not sim and not previous:
        return lambda: None
    set_param(uri, "/use_sim_time", sim)

    def restore() -> None:
        with contextlib.suppress(OSError, LowerbaseError):
            if previous is None:
                delete_param(uri, "/use_sim_time")
            else:
                set_param(uri, "/use_sim_time", previous)

    return restore


def _run_lockstep(args: argparse.Namespace, sup: Any, speed: float, parts: tuple[str, ...],
                  line: Any, log_dir: Path, uri: str) -> int:
    """--sim-time: the recorder child (if asked) and the lockstep robot in this process."""
    from lowerbase.robot.lockstep import LockstepOptions
    from lowerbase.robot.plan import RobotOptions, recorder_spec
    from lowerbase.robot.simrun import SimRun, run_sim

    if args.mcap or args.foxglove:
        sup.start([recorder_spec(RobotOptions(map=args.map, foxglove=args.foxglove,
                                              mcap=args.mcap))], on_ready=_on_ready)
    opts = LockstepOptions(map=args.map, parts=parts, soc=args.soc,
                           ground_truth=args.ground_truth, seed=args.seed, truth=args.truth,
                           camera=args.camera)

    lost: set[str] = set()

    def alive() -> str | None:
        for child in sup.children:
            if child.poll() is not None and child.spec.name not in lost:
                if not child.spec.essential:
                    lost.add(child.spec.name)
                    _on_lost(child)
                    continue
                return f"{child.spec.name} (see {child.log_path})"
        return None

    stats = run_sim(SimRun(opts, None if speed == MAX_SPEED else speed, args.paused,
                           args.duration, legged=args.robot == "legged"), lambda text: line.show(
                               f"lowerbase robot: {text} | master {uri}", time.monotonic()),
                    alive)
    line.done()
    counts = ", ".join(f"{k} {v}" for k, v in sorted(stats.items()) if v)
    print(f"lowerbase robot: stopped; {counts or 'nothing counted'}; logs in {log_dir}",
          flush=True)
    return 0


#: what ``robot --ros2`` without --sim-time says: real time on ROS 2 is the driver's alone
ROS2_SIM_TIME = ("lowerbase robot: on ROS 2 the robot runs on simulated time, as with "
                 "--sim-time (/clock; give your nodes use_sim_time:=true); for real firmware "
                 "on ROS 2 run lowerbase driver --ros2 on its bus (docs/ros2.md)")


def _run_ros2(args: argparse.Namespace) -> int:
    """--ros2: the lockstep robot (wheeled or legged) with its interface on ROS 2 (no ROS
    master)."""
    from lowerbase.robot.lockstep import LockstepOptions, LockstepRobot
    from lowerbase.robot.plan import UPPER
    from lowerbase.world.maps import load_map

    for given, flag in ((args.mcap or args.foxglove, "--mcap/--foxglove"),
                        (args.respawn, "--respawn")):
        if given:
            raise ConfigError(f"{flag} is not on ROS 2 yet (docs/ros2.md)")
    from lowerbase.cli.driver import split_ros_args
    from lowerbase.driver.ros2_node import import_rclpy

    ros_args = split_ros_args(args.ros_args)
    import_rclpy()  # one clear line when rclpy or the messages are missing
    load_map(args.map)
    if not args.sim_time:  # the virtual robot on ROS 2 is the lockstep one, said in one line
        print(ROS2_SIM_TIME, file=sys.stderr, flush=True)
    from lowerbase.robot.lockstep_ros2 import run as run_ros2

    speed = args.speed or DEFAULT_SPEED
    opts = LockstepOptions(map=args.map, parts=tuple(p for p in UPPER if p not in args.without),
                           soc=args.soc, ground_truth=args.ground_truth, seed=args.seed,
                           truth=args.truth, camera=args.camera)
    make: Any = LockstepRobot
    if args.robot == "legged":  # its lower computer and legged driver (parts, map unused)
        from lowerbase.robot.lockstep_legged import LeggedLockstep

        make = LeggedLockstep
    return run_ros2(opts, None if speed == MAX_SPEED else speed, ros_args,
                    duration=args.duration, make=make, paused=args.paused)


def run(args: argparse.Namespace) -> int:
    from lowerbase.robot.master import (
        master_answers,
        master_uri,
        own_master,
        running_robot,
        wait_for_master,
    )
    from lowerbase.robot.partdown import PartReport
    from lowerbase.robot.plan import UPPER, RobotOptions, robot_plan
    from lowerbase.robot.supervisor import Supervisor
    from lowerbase.scenarios.demo import StatusLine
    from lowerbase.world.maps import load_map

    if args.robot == "legged" and args.camera:
        raise ConfigError("--camera is the wheeled robot's depth camera; the legged robot has "
                          "none: drop --camera")
    if getattr(args, "ros2", False):
        return _run_ros2(args)
    if args.ros_args:
        raise ConfigError(f"{args.ros_args[0]}: NAME:=VALUE arguments go with --ros2; on ROS 1 "
                          "the robot reads the parameter server (rosparam set "
                          "/move_base/recovery_behaviors ...)")
    if not args.sim_time:
        for given, flag, why in (
                (args.speed is not None, "--speed K", "real time runs at 1 x"),
                (args.paused, "--paused", "real time does not wait"),
                (args.seed != 0, "--seed S", "only a lockstep run repeats"),
                (args.robot == "legged", "--robot legged", "the legged robot is lockstep only")):
            if given:
                raise ConfigError(f"{flag} goes with --sim-time ({why})")
        if args.camera:
            raise ConfigError("--camera goes with --sim-time: the real-time robot's world "
                              "renders the camera always")
    elif args.respawn:
        raise ConfigError("--respawn restarts the parts of the real-time robot; with "
                          "--sim-time the robot is one process: drop one of them")
    speed = (args.speed or DEFAULT_SPEED) if args.sim_time else None
    load_map(args.map)  # a wrong map is one line now, not a part ending later
    if args.mcap is not None and Path(args.mcap).suffix.lower() != ".mcap":
        raise ConfigError(f"--mcap {args.mcap}: the file name must end in .mcap")
    if args.foxglove is not None:
        _check_listen(args.foxglove)
    for value, flag in ((args.mcap, "--mcap"), (args.truth, "--truth")):
        if value is not None:
            output_file(value, flag)
    log_dir = output_dir(args.log_dir, "--log-dir", make=True) if args.log_dir else Path(
        tempfile.mkdtemp(prefix="lowerbase-robot-"))
    uri = master_uri()
    sup = Supervisor(log_dir)
    previous = {s: signal.signal(s, lambda *_: sup.request_stop())
                for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    line = StatusLine(force=False)
    started = time.monotonic()
    ended = None
    restore: Any = lambda: None  # noqa: E731
    watch, unwatch = None, None
    report: PartReport | None = None
    try:
        if not master_answers(uri):
            sup.start([own_master(uri)])
            wait_for_master(uri)
            print(f"lowerbase robot: started a ROS master at {uri}", flush=True)
        else:
            other = running_robot(uri)
            if other is not None:
                raise ConfigError(f"the ROS master at {uri} has a robot running already "
                                  f"({other}): stop it first, or give this one a master of "
                                  "its own (ROS_MASTER_URI=http://localhost:PORT)")
        restore = _use_sim_time(uri, speed is not None)  # before any node starts
        parts = tuple(p for p in UPPER if p not in args.without)
        if speed is not None:
            return _run_lockstep(args, sup, speed, parts, line, log_dir, uri)
        report = PartReport(uri)
        report.clear()
        sup.start(robot_plan(RobotOptions(map=args.map, parts=parts, foxglove=args.foxglove,
                                          sim_speed=speed, truth=args.truth,
                                          mcap=args.mcap, soc=args.soc,
                                          ground_truth=args.ground_truth,
                                          respawn=args.respawn)),
                  on_ready=_on_ready)
        print(f"lowerbase robot: ready on ROS master {uri}; logs in {log_dir}; Ctrl-C stops",
              flush=True)
        if speed is not None:
            from lowerbase.robot.simclock import ClockWatch, watch_clock

            watch = ClockWatch()
            unwatch = watch_clock(watch)
        deadline = None if args.duration is None else started + args.duration

        def tick() -> None:
            line.show(_status(sup, started, uri, watch), time.monotonic())
            if deadline is not None and time.monotonic() >= deadline:
                sup.request_stop()

        def down(child: Any) -> None:
            _report_down(report, sup, child)

        def respawned(old: Any, new: Any) -> None:
            _on_respawn(old, new)
            report.up()

        ended = sup.watch(on_tick=tick, on_lost=_on_lost, on_respawn=respawned, on_down=down)
    except KeyboardInterrupt:
        pass
    finally:
        line.done()
        if watch is not None:
            print(f"lowerbase robot: {watch.status()}", flush=True)
        if unwatch is not None:
            unwatch()
        codes = sup.stop_all()
        if report is not None:
            report.close()
        restore()
        for s, handler in previous.items():
            signal.signal(s, handler)
    for child in sup.children:  # an emulator that could not keep real time says so at its end
        for said in child.tail(3):
            if "fell behind real time" in said:
                print(f"lowerbase robot: {child.spec.name}: {said.rpartition('; ')[2]} (see "
                      f"{child.log_path})", flush=True)
    if ended is not None:
        last = " | ".join(ended.final_lines or ended.tail(3)) or ended.last_line or "no output"
        print(f"lowerbase robot: error: {ended.spec.name} ended (exit code "
              f"{codes.get(ended.spec.name)}): {clip(last, 600)}; see {ended.log_path}",
              file=sys.stderr)
        return 1
    print(f"lowerbase robot: stopped; logs in {log_dir}", flush=True)
    return 0
