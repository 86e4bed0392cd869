"""``lowerbase tasks``: the vendor's exec_task service and robot_status topic as a ROS1 node.

Runs beside ``lowerbase navigation`` (/move_base, /cmd_vel_control), ``lowerbase world``
(movebase_pose2d) and ``lowerbase driver`` (link state, status code, battery, BMS). Give it the
same ``--map`` as the world: its places (mark_no storage points, the charger) are the targets.
"""

from __future__ import annotations

import argparse
from typing import Any


def add_subparser(subparsers: Any) -> None:
    from lowerbase.cli.driver import RosArgvParser

    p = subparsers.add_parser(
        "tasks",
        help="run the ROS1 node tasks: exec_task and robot_status (transport, charging)",
        description="Run the ROS1 node tasks on the master in ROS_MASTER_URI: the exec_task "
        "service (woosh_msgs/ExecTask) and the robot_status topic (woosh_msgs/RobotStatus, "
        "latched, on change) of the vendor's interface (docs/tasks.md). Tasks drive through "
        "lowerbase navigation's /move_base and /cmd_vel_control.",
        epilog="ROS arguments pass through (remappings, __name:=, __ns:=).",
    )
    p.__class__ = RosArgvParser
    p.add_argument("--map", default="warehouse", metavar="NAME|FILE",
                   help="a shipped map (warehouse, corridor_loop, empty_room) or a map_server "
                   "YAML file with its places; the same as lowerbase world's (default warehouse)")
    p.add_argument("--load-time", type=float, default=10.0, metavar="S",
                   help="duration of the timed loading action (default 10)")
    p.add_argument("--unload-time", type=float, default=10.0, metavar="S",
                   help="duration of the timed unloading action (default 10)")
    p.add_argument("--full-soc", type=float, default=100.0, metavar="PERCENT",
                   help="a charging task undocks at this charge (default 100)")
    p.add_argument("--blocked-delay", type=float, default=0.5, metavar="S",
                   help="warn \"path blocked\" on robot_status only after navigation reports "
                   "the path blocked this long in a row (0: at once; default 0.5)")
    p.add_argument("--no-auto-charge", action="store_true",
                   help="do not go and charge on a low battery by itself")
    p.add_argument("ros_args", nargs="*", metavar="NAME:=VALUE",
                   help="ROS remappings and special keys")
    p.set_defaults(func=run)


#: TaskConfig's fields set by options, and the option's name
OPTIONS = {"load_time": "--load-time", "unload_time": "--unload-time", "full_soc": "--full-soc",
           "blocked_delay": "--blocked-delay"}


def task_config(args: argparse.Namespace) -> Any:
    """The TaskConfig of the options; a bad value is a ConfigError line naming the option."""
    from lowerbase.errors import ConfigError, LowerbaseError
    from lowerbase.tasks.plan import TaskConfig

    try:
        return TaskConfig(**{field: getattr(args, field) for field in OPTIONS},
                          auto_charge=not args.no_auto_charge)
    except LowerbaseError as exc:
        msg = str(exc)
        for field, option in OPTIONS.items():
            msg = msg.replace(f"task config {field} ", f"{option} ")
        raise ConfigError(msg) from None


def run(args: argparse.Namespace) -> int:
    from lowerbase.cli.driver import split_ros_args
    from lowerbase.tasks import node
    from lowerbase.world.maps import load_map
    from lowerbase.world.places import load_places

    ros_args = split_ros_args(args.ros_args)
    grid = load_map(args.map)
    places = load_places(args.map, grid)
    config = task_config(args)
    setup = node.TasksSetup(places, config)
    node.import_ros()  # one clear line when ROS is missing, before anything starts
    where = (f"map {args.map}: {len(places.storage)} storage points, "
             f"{'a charger' if places.charger else 'no charger'}")
    return node.run(setup, ros_args, where)
