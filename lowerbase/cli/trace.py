"""``lowerbase trace``: TraceNavigate and ObstacleNavigate (shared/seeds/001) as a ROS1 node.

Runs beside ``lowerbase emulate``, ``lowerbase driver`` (it takes /base_cmd_vel) and ``lowerbase
world`` (/scan, TF map -> odom); give it the same ``--map`` as the world. docs/trace.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_subparser(subparsers: Any) -> None:
    from lowerbase.cli.driver import RosArgvParser

    p = subparsers.add_parser(
        "trace",
        help="run the ROS1 node trace_navigate: the seed's TraceNavigate and ObstacleNavigate",
        description="Run TraceNavigate and ObstacleNavigate on the master in ROS_MASTER_URI: "
        "the topics msg_trace_navigate_route/_status, msg_obstacle_navigate_route/_status, "
        "msg_robot_laser_data, msg_robot_global_pos and msg_robot_speed_control carry the "
        "seed's protobuf messages in lowerbase_msgs/Protobuf; /scan, TF map -> base_link and "
        "driver_base's /base_cmd_vel are bridged to them (docs/trace.md). Follows ROS time "
        "(/use_sim_time).",
        epilog="ROS arguments pass through (remappings, __name:=, __ns:=).",
    )
    p.__class__ = RosArgvParser
    p.add_argument("--map", default="warehouse", metavar="NAME|FILE",
                   help="a shipped map (warehouse, corridor_loop, empty_room) or a map_server "
                   "YAML file; the same as lowerbase world's (default warehouse). A list whose "
                   "map field names another map is refused")
    p.add_argument("--status-period", type=float, default=5.0, metavar="S",
                   help="RUNNING reports every S seconds (default 5)")
    p.add_argument("--blocked-timeout", type=float, default=60.0, metavar="S",
                   help="stopped by an obstacle S seconds: BLOCKED (default 60)")
    p.add_argument("--speed", type=float, default=0.5, metavar="M/S",
                   help="speed of points without one (default 0.5)")
    p.add_argument("--cmd-vel", default="base_cmd_vel", choices=("base_cmd_vel",
                                                                  "smooth_cmd_vel"),
                   help="driver_base's topic msg_robot_speed_control goes to (default "
                   "base_cmd_vel: raw; smooth_cmd_vel: the lower computer's ramps)")
    p.add_argument("--no-bridges", action="store_true",
                   help="do not bridge /scan, TF and the speed command (other nodes publish "
                   "msg_robot_laser_data and msg_robot_global_pos and take "
                   "msg_robot_speed_control)")
    p.add_argument("ros_args", nargs="*", metavar="NAME:=VALUE",
                   help="ROS remappings and special keys")
    p.set_defaults(func=run)


def map_name(ref: str) -> str:
    """The name a GTraceList's ``map`` field must hold: a shipped map's name, a file's stem."""
    return Path(ref).stem if ref.endswith((".yaml", ".yml")) else ref


def run(args: argparse.Namespace) -> int:
    from lowerbase.cli.driver import split_ros_args
    from lowerbase.trace import node
    from lowerbase.trace.base import TraceParams
    from lowerbase.world.maps import load_map

    ros_args = split_ros_args(args.ros_args)
    grid = load_map(args.map)
    params = TraceParams(status_period=args.status_period,
                         blocked_timeout=args.blocked_timeout, default_speed=args.speed,
                         map_name=map_name(args.map))
    setup = node.TraceSetup(grid, params, bridges=not args.no_bridges, cmd_vel=args.cmd_vel)
    node.import_ros()  # one clear line when ROS or lowerbase_msgs is missing
    return node.run(setup, ros_args, f"map {params.map_name!r}")
