"""``lowerbase navigation``: move_base, step control and navigation modes as a ROS1 node.

Runs beside ``lowerbase world`` (the localization: TF map -> odom, /scan, the camera's cloud),
``lowerbase driver`` (/odom, /driver_base/parameter; it takes /base_cmd_vel) and ``lowerbase
emulate``. Give it the same ``--map`` as the world.
"""

from __future__ import annotations

import argparse
from typing import Any


def add_subparser(subparsers: Any) -> None:
    from lowerbase.cli.driver import RosArgvParser

    p = subparsers.add_parser(
        "navigation",
        help="run the ROS1 node move_base: costmaps, planning, /move_base, /cmd_vel_control",
        description="Run the ROS1 node move_base on the master in ROS_MASTER_URI: the "
        "/move_base, /cmd_vel_control and /navigation_mode action servers (woosh_msgs), "
        "/move_base/make_plan, /move_base/enable_costmaps, /move_base/clear_costmaps, the "
        "set_footprint topics and the costmap and plan topics (docs/navigation.md). It drives "
        "through /base_cmd_vel (lowerbase driver) and needs lowerbase world's localization.",
        epilog="ROS arguments pass through (remappings, __name:=, __ns:=).",
    )
    p.__class__ = RosArgvParser
    p.add_argument("--map", default="warehouse", metavar="NAME|FILE",
                   help="a shipped map (warehouse, corridor_loop, empty_room) or a map_server "
                   "YAML file; the same as lowerbase world's (default warehouse)")
    p.add_argument("--profile", metavar="FILE",
                   help="robot profile TOML whose [sensors] camera to use (default: packaged)")
    p.add_argument("--no-camera", action="store_true",
                   help="do not subscribe the camera's cloud_without_planes (/scan only)")
    p.add_argument("--rate", type=float, default=20.0, metavar="HZ",
                   help="control rate: /base_cmd_vel while a goal runs (default 20)")
    p.add_argument("ros_args", nargs="*", metavar="NAME:=VALUE",
                   help="ROS remappings and special keys")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from lowerbase.cli.driver import split_ros_args
    from lowerbase.navigation import node
    from lowerbase.world.maps import load_map
    from lowerbase.world.sensors import sensors_from_profile_file

    ros_args = split_ros_args(args.ros_args)
    grid = load_map(args.map)
    camera = None if args.no_camera else sensors_from_profile_file(args.profile).camera
    setup = node.NavigationSetup(grid, camera, rate_hz=args.rate)
    node.import_ros()  # one clear line when ROS is missing, before anything starts
    return node.run(setup, ros_args, f"map {args.map}")
