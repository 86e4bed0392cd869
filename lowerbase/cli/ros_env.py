"""``lowerbase ros-env``: print the shell line that lets the ROS tools find woosh_msgs and the
package lowerbase_driver (``eval "$(lowerbase ros-env)"``)."""

from __future__ import annotations

import argparse
import sys
from typing import Any


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "ros-env",
        help="print export ROS_PACKAGE_PATH=... for rostopic, rosbag and roslaunch",
        description="Print the export line that puts the generated woosh_msgs (python -m "
        "lowerbase.driver.msggen) and the ROS package lowerbase_driver (driver_base.launch) "
        "on ROS_PACKAGE_PATH, so that rosmsg, rostopic, rosbag and roslaunch find them.",
        epilog='Use it as: eval "$(lowerbase ros-env)"',
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from lowerbase.driver.msggen import env_lines

    sys.stdout.write(env_lines())
    return 0
