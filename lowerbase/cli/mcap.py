"""``lowerbase mcap``: convert between MCAP and rosbag, and summarise an MCAP file.

``to-bag`` and ``from-bag`` copy messages unchanged (ROS1 bytes are the same in both formats;
``lowerbase.recording.convert``); ``info`` lists the topics, types and counts; ``recover``
rewrites a recording cut short (no footer) as a whole file. No ROS needed.
"""

from __future__ import annotations

import argparse
from typing import Any

from lowerbase.files import output_file


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "mcap", help="convert MCAP <-> rosbag (.bag), list an MCAP file's topics",
        description="MCAP recordings (scenario run, demo, record; docs/recording.md) and "
        "ROS1 bags, both ways, without a ROS install.")
    sub = p.add_subparsers(title="actions", dest="mcap_command", metavar="ACTION")
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
    to_bag = sub.add_parser("to-bag", help="MCAP -> rosbag (JSON channels become "
                            "std_msgs/String)")
    to_bag.add_argument("input", metavar="IN.mcap")
    to_bag.add_argument("output", metavar="OUT.bag")
    to_bag.set_defaults(func=to_bag_command)
    from_bag = sub.add_parser("from-bag", help="rosbag -> MCAP (ROS1 channels)")
    from_bag.add_argument("input", metavar="IN.bag")
    from_bag.add_argument("output", metavar="OUT.mcap")
    from_bag.set_defaults(func=from_bag_command)
    recover = sub.add_parser("recover", help="a recording cut short (no footer: a killed "
                             "recorder) -> a whole MCAP file with what could be read")
    recover.add_argument("input", metavar="IN.mcap")
    recover.add_argument("output", metavar="OUT.mcap")
    recover.set_defaults(func=recover_command)
    info = sub.add_parser("info", help="topics, message types and counts of an MCAP file")
    info.add_argument("input", metavar="FILE.mcap")
    info.set_defaults(func=info_command)


def _report(done: Any, output: str) -> None:
    print(f"{done.messages} message(s) on {len(done.topics)} topic(s) -> {output}")
    for topic, n in sorted(done.skipped.items()):
        print(f"skipped {topic}: {n} message(s) of an encoding rosbag cannot hold")


def to_bag_command(args: argparse.Namespace) -> int:
    from lowerbase.recording.convert import mcap_to_bag

    _report(mcap_to_bag(args.input, output_file(args.output)), args.output)
    return 0


def from_bag_command(args: argparse.Namespace) -> int:
    from lowerbase.recording.convert import bag_to_mcap

    _report(bag_to_mcap(args.input, output_file(args.output)), args.output)
    return 0


def info_command(args: argparse.Namespace) -> int:
    from lowerbase.recording.convert import mcap_summary

    for line in mcap_summary(args.input):
        print(line)
    return 0


def recover_command(args: argparse.Namespace) -> int:
    from lowerbase.recording.convert import recover_mcap

    done = recover_mcap(args.input, output_file(args.output))
    where = f"; reading stopped at: {done.damage}" if done.damage else "; the file was whole"
    print(f"{done.messages} message(s) on {len(done.topics)} topic(s) -> {args.output}{where}")
    return 0
