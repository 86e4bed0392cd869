"""``lowerbase driver``: run the ROS1 node driver_base against a lower computer."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any


def is_ros_arg(arg: str) -> bool:
    """A ROS remapping or special key (``name:=value``, ``__name:=x``, ``_param:=v``)."""
    return ":=" in arg and not arg.startswith("-")


class RosArgvParser(argparse.ArgumentParser):
    """Takes the ROS arguments out before parsing, wherever they stand.

    roslaunch appends ``__name:=... __log:=...`` after the node's own arguments, which may end
    in an option with a variable number of values (``--bus-kwargs port=1 __name:=x``); without
    this, that option would swallow them.
    """

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None,
    ) -> tuple[argparse.Namespace, list[str]]:
        import sys

        argv = list(sys.argv[1:] if args is None else args)
        ros = [a for a in argv if is_ros_arg(a)]
        ns, extra = super().parse_known_args([a for a in argv if not is_ros_arg(a)], namespace)
        ns.ros_args = [*getattr(ns, "ros_args", []), *ros]
        return ns, extra


def add_subparser(subparsers: Any) -> None:
    from lowerbase.transport import add_bus_arguments

    p = subparsers.add_parser(
        "driver",
        help="run the ROS1 node driver_base (the upper computer's chassis interface)",
        description="Run the ROS1 node driver_base: it talks to the lower computer (the "
        "emulated one or real firmware) over CAN or serial and provides the chassis topics "
        "(/odom_raw, /odom, /imu/data_raw, /battery, ...; docs/driver.md). With no bus option "
        "it uses udp_multicast 239.74.163.2:43113, where `lowerbase emulate` listens by "
        "default. Needs a running ROS master (roscore) and the generated woosh_msgs.",
        epilog="ROS arguments pass through: remappings (odom:=odom2, /odom:=/wheel/odom), "
        "__name:=NAME, __ns:=NS and private parameters (_publish_tf:=false). Parameters and "
        "their defaults: lowerbase/driver/config/driver_base.yaml.",
    )
    p.__class__ = RosArgvParser  # add_parser builds the class chosen by the main parser
    add_bus_arguments(p)
    p.add_argument("--robot", choices=("wheeled", "legged"), default="wheeled",
                   help="wheeled (default): driver_base for the differential-drive chassis; "
                   "legged: legged_driver, the quadruped's seed interface (robot_state, "
                   "planning/*, set_map, set_listen) over four leg buses: udp_multicast ports "
                   "PORT..PORT+3 (docs/legged.md)")
    p.add_argument("--replay", metavar="FILE",
                   help="feed a python-can log (.log, .asc, .blf, ...) through the driver "
                   "instead of a live bus, with its original timing; the node stops at its "
                   "end (commands go nowhere)")
    p.add_argument("--replay-profile", metavar="FILE",
                   help="for a recording that starts after the driver's parameter exchange: "
                   "answer the driver's parameter reads with the [chassis] parameters of this "
                   "robot profile ('default': the packaged one)")
    p.add_argument("--replay-param", action="append", default=[], metavar="NAME=VALUE",
                   help="one such parameter by its wire name (e.g. wheelPerimeter=0.6283), "
                   "over --replay-profile or the packaged profile (repeatable)")
    p.add_argument("--ros2", action="store_true",
                   help="driver_base on ROS 2 instead (the same topics, services and "
                   "parameters; run from .venv-ros2 after `make ros2`, docs/ros2.md)")
    p.add_argument("ros_args", nargs="*", metavar="NAME:=VALUE",
                   help="ROS remappings and special keys (see below)")
    p.set_defaults(func=run)


def split_ros_args(args: list[str]) -> list[str]:
    """The ROS arguments of ``args``; anything else is a ConfigError (one clear line)."""
    from lowerbase.errors import ConfigError

    try:
        import rospy

        stray = rospy.myargv(["driver", *args])[1:]
    except ImportError:
        stray = [a for a in args if not is_ros_arg(a)]
    if stray:
        raise ConfigError(f"unexpected argument {stray[0]!r} (ROS arguments look like "
                          "NAME:=VALUE)")
    return list(args)


def replay_parameters(args: argparse.Namespace) -> dict[str, float] | None:
    """The parameters --replay-profile/--replay-param give (wire names), or None."""
    from lowerbase.errors import ConfigError
    from lowerbase.firmware_model.profile import ChassisParams, load_profile

    profile = getattr(args, "replay_profile", None)
    pairs = getattr(args, "replay_param", None) or []
    if profile is None and not pairs:
        return None
    if not args.replay:
        raise ConfigError("--replay-profile and --replay-param go with --replay FILE")
    base = load_profile(None if profile in (None, "default") else profile).chassis
    values: dict[str, float] = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        try:
            values[name.strip()] = float(text)
        except ValueError:
            sep = ""
        if not sep:
            raise ConfigError(f"--replay-param {pair!r}: expected NAME=VALUE, e.g. "
                              "wheelPerimeter=0.6283") from None
    return ChassisParams.from_wire_dict(values, base).as_wire_dict()


def run(args: argparse.Namespace) -> int:
    import sys

    from lowerbase.driver import node
    from lowerbase.errors import ConfigError, LowerbaseError

    ros_args = split_ros_args(args.ros_args)
    if getattr(args, "robot", "wheeled") == "legged":
        if getattr(args, "ros2", False):
            raise ConfigError("--ros2 is for the wheeled robot so far (docs/ros2.md)")
        return run_legged(args, ros_args)
    parameters = replay_parameters(args)
    ros2 = getattr(args, "ros2", False)
    if ros2:
        from lowerbase.driver import ros2_node as ros2_driver

        ros2_driver.import_rclpy()  # one clear line when rclpy or the messages are missing
    else:
        node.import_ros()  # one clear line when ROS or woosh_msgs is missing, first
    if args.replay:
        if args.serial or getattr(args, "interface", None) or getattr(args, "channel", None):
            raise ConfigError("--replay replaces the bus: drop the bus options")
        replay = node.ReplayLink(args.replay, parameters=parameters)  # checked before rospy
        if replay.advice:
            print(f"lowerbase driver: {replay.advice}", file=sys.stderr, flush=True)

        def link_factory(finished: Any) -> Any:
            replay.finished = finished
            return replay
    else:
        replay = None
        from lowerbase.transport import config_from_args

        config = config_from_args(args)

        def link_factory(finished: Any) -> Any:
            return bus_link(config)

    code = (ros2_driver.run if ros2 else node.run)(link_factory, ros_args)
    if replay is not None:
        if replay.skipped_lines:
            print(f"lowerbase driver: {replay.skipped_lines} line(s) of {replay.path.name} were "
                  "not frames and were skipped", file=sys.stderr, flush=True)
        if replay.error is not None:  # corrupt or truncated: the replay did not reach the end
            raise LowerbaseError(f"{replay.error}; the replay stopped there "
                                 f"({replay.frames} frames replayed)")
    return code


def bus_link(config: dict[str, Any]) -> Any:
    """The driver's live link; a serial device that is not there yet is waited for, and the
    user told so in one line (and when it opens)."""
    from lowerbase.driver.links import BusLink

    def say(text: str) -> None:
        print(f"lowerbase driver: {text}", flush=True)

    return BusLink(config, announce=say)


def run_legged(args: argparse.Namespace, ros_args: list[str]) -> int:
    from lowerbase.errors import ConfigError
    from lowerbase.legged_driver import node as legged_node
    from lowerbase.transport import config_from_args

    if args.replay or args.replay_profile or args.replay_param:
        raise ConfigError("--replay is for the wheeled robot; drop it with --robot legged")
    if args.serial:
        raise ConfigError("the legged robot is on four CAN buses: drop --serial")
    legged_node.import_ros()  # one clear line when ROS or lowerbase_legged_msgs is missing
    return legged_node.run(config_from_args(args), ros_args)
