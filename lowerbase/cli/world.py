"""``lowerbase world``: the chassis' map, /scan, cameras and localization as a ROS1 node.

The placement options (``--map``, ``--obstacles``, ``--initial-pose``/``--place``) are shared
with ``lowerbase emulate --map``, so that the emulator's robot collides with the same world the
sensors see: give both commands the same ones.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass
from typing import Any

#: the place a map's robot starts at when neither --initial-pose nor --place is given
DEFAULT_PLACE = "start"


def add_world_arguments(p: Any, map_default: str | None) -> None:
    """--map, --obstacles, --initial-pose | --place (also used by ``lowerbase emulate``)."""
    p.add_argument("--map", default=map_default, metavar="NAME|FILE",
                   help="a shipped map (warehouse, corridor_loop, empty_room) or a map_server "
                   f"YAML file{' (default ' + map_default + ')' if map_default else ''}")
    p.add_argument("--obstacles", metavar="FILE",
                   help="obstacles the map does not know: a TOML file of [[obstacles]] tables "
                   "(kind = \"box\" or \"person\"; docs/world.md)")
    start = p.add_mutually_exclusive_group()
    start.add_argument("--initial-pose", metavar="X,Y,YAW",
                       help="where the robot starts on the map [m, m, rad] (default: the map's "
                       f"place {DEFAULT_PLACE!r})")
    start.add_argument("--place", metavar="NAME",
                       help="start at a named place of the map (a mark_no, charger, start, ...)")


@dataclass
class WorldParts:
    grid: Any
    obstacles: Any
    start: tuple[float, float, float]
    where: str


def world_parts(args: argparse.Namespace) -> WorldParts:
    """The map, obstacles and start pose the options name; one-line errors if bad."""
    from lowerbase.errors import ConfigError
    from lowerbase.files import read_toml
    from lowerbase.world.footprint import validate_pose
    from lowerbase.world.maps import load_map
    from lowerbase.world.obstacles import Obstacles, obstacles_from_dicts
    from lowerbase.world.places import load_places

    grid = load_map(args.map)
    obstacles = Obstacles()
    if args.obstacles:
        doc = read_toml(args.obstacles, "obstacles file")
        specs = doc.get("obstacles")
        if not isinstance(specs, list) or set(doc) - {"obstacles"}:
            raise ConfigError(f"{args.obstacles}: expected only [[obstacles]] tables")
        obstacles = obstacles_from_dicts(specs)
    if args.initial_pose:
        start = parse_pose(args.initial_pose)
        where = f"({start[0]:g}, {start[1]:g}, {start[2]:g})"
    else:
        name = args.place or DEFAULT_PLACE
        places = load_places(args.map, grid)
        if not args.place and DEFAULT_PLACE not in places.named():
            raise ConfigError(f"map {args.map!r} has no place {DEFAULT_PLACE!r}: give "
                              "--initial-pose X,Y,YAW or --place NAME")
        start = places.pose(name)
        where = f"place {name!r}"
    start = validate_pose(start, grid, obstacles, 0.0, what="the robot's start pose")
    return WorldParts(grid, obstacles, start, where)


def parse_pose(text: str) -> tuple[float, float, float]:
    from lowerbase.errors import ConfigError

    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ConfigError(f"--initial-pose {text!r}: expected three finite numbers X,Y,YAW "
                          "[m, m, rad], e.g. 4.0,4.0,0.0")
    return values[0], values[1], values[2]


def add_subparser(subparsers: Any) -> None:
    from lowerbase.cli.driver import RosArgvParser

    p = subparsers.add_parser(
        "world",
        help="run the ROS1 node world: map, /scan, cameras and localization",
        description="Run the ROS1 node world on the master in ROS_MASTER_URI: the latched /map "
        "and aic_map_server/get_map, /scan (the merged lidars), the camera_1 topics, "
        "localization (/amcl_pose, movebase_pose2d, TF map->odom; /start_localization, "
        "/initialpose, set_map) and the sensors' static TFs (docs/world.md). The robot's "
        "true pose comes from `lowerbase emulate --truth-udp`; /odom from `lowerbase driver`.",
        epilog="ROS arguments pass through (remappings, __name:=, __ns:=).",
    )
    p.__class__ = RosArgvParser
    add_world_arguments(p, "warehouse")
    p.add_argument("--truth-udp", nargs="?", const="", default="", metavar="[HOST:]PORT",
                   help="where to listen for the emulator's ground truth (default "
                   "127.0.0.1:43213, as lowerbase emulate --truth-udp sends)")
    p.add_argument("--ground-truth", action="store_true",
                   help="publish the true pose instead of the particle filter's (tests)")
    p.add_argument("--no-camera", action="store_true", help="no camera topics (saves CPU)")
    p.add_argument("--camera-hz", type=_rate, metavar="HZ",
                   help="the camera's frame rate (default: the profile's, 15 Hz); a frame "
                   "costs tens of ms of CPU, so a busy host keeps a lower rate better (a rate "
                   "it cannot keep is logged every 30 s with the rate achieved)")
    p.add_argument("--publish-clock", action="store_true",
                   help="be the simulator: publish /clock from the ground truth's time, for "
                   "nodes with /use_sim_time true (lowerbase robot --sim-time)")
    p.add_argument("--profile", metavar="FILE",
                   help="robot profile TOML whose [sensors] to use (default: packaged)")
    p.add_argument("ros_args", nargs="*", metavar="NAME:=VALUE",
                   help="ROS remappings and special keys")
    p.set_defaults(func=run)


def _rate(text: str) -> float:
    try:
        hz = float(text)
    except ValueError:
        hz = 0.0
    if not 0.1 <= hz <= 90.0:
        raise argparse.ArgumentTypeError(f"must be a rate in Hz within 0.1..90, not {text!r}")
    return hz


def run(args: argparse.Namespace) -> int:
    from lowerbase.cli.driver import split_ros_args
    from lowerbase.world import node
    from lowerbase.world.sensors import sensors_from_profile_file
    from lowerbase.world.truth_stream import TruthReceiver, parse_address

    ros_args = split_ros_args(args.ros_args)
    host, port = parse_address(args.truth_udp)
    parts = world_parts(args)
    sensors = sensors_from_profile_file(args.profile)
    if args.camera_hz is not None and sensors.camera is not None:
        sensors = dataclasses.replace(
            sensors, camera=dataclasses.replace(sensors.camera, rate_hz=args.camera_hz))
    setup = node.WorldSetup(parts.grid, sensors, parts.start,
                            parts.obstacles, ground_truth=args.ground_truth,
                            camera=not args.no_camera)
    node.import_ros()  # one clear line when ROS is missing, before binding anything
    with TruthReceiver(host, port) as truth:
        print(f"lowerbase world: map {args.map}, robot starts at {parts.where}; waiting for the "
              f"ground truth on udp {host}:{truth.address[1]} (lowerbase emulate "
              f"--truth-udp)", flush=True)
        where = f"udp {host}:{truth.address[1]}"
        if not getattr(args, "publish_clock", False):
            return node.run(setup, truth, ros_args, where)
        from lowerbase.world.sim_clock import ClockedTruth

        clocked = ClockedTruth(truth)
        try:
            return node.run(setup, clocked, ros_args, f"{where}; publishing /clock from it")
        finally:
            clocked.close()
