"""``lowerbase ros2-env``: print the shell lines that put the ROS 2 venv (``make ros2``) and its
built interface packages (woosh_msgs, tf2_msgs, nav2_msgs, lowerbase_legged_msgs) on a shell's
path (``eval "$(lowerbase ros2-env)"``)."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "ros2-env",
        help="print the exports for ROS 2 (.venv-ros2, made by make ros2)",
        description="Print the export lines that put .venv-ros2 (ROS 2 Kilted from PyPI wheels) "
        "first on PATH and the interface packages built by make ros2 (woosh_msgs, tf2_msgs, "
        "nav2_msgs, lowerbase_legged_msgs) on AMENT_PREFIX_PATH and LD_LIBRARY_PATH, with "
        "discovery kept to this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).",
        epilog='Use it as: eval "$(lowerbase ros2-env)"; ROS2_VENV names another venv.',
    )
    p.add_argument("--venv", type=Path, default=None,
                   help="the ROS 2 venv (default: $ROS2_VENV or .venv-ros2 in the repository)")
    p.set_defaults(func=run)


def ros2_paths(venv: Path | None = None) -> tuple[Path, Path]:
    """The ROS 2 venv and the install of the current interface definitions; ConfigError when
    ``make ros2`` has not made them."""
    from lowerbase.ros2.interfaces import REPO, cache_dir

    if venv is None:
        venv = Path(os.environ.get("ROS2_VENV") or REPO / ".venv-ros2")
    venv = venv if venv.is_absolute() else REPO / venv
    if not (venv / "bin" / "python").exists():
        raise ConfigError(f"no ROS 2 venv at {venv}: run make ros2")
    cache = cache_dir()
    if not (cache / ".complete").exists():
        raise ConfigError(f"the ROS 2 interface packages of these definitions are not built "
                          f"({cache}): run make ros2")
    return venv, cache / "install"


def run(args: argparse.Namespace) -> int:
    from lowerbase.ros2.interfaces import env_for

    venv, install = ros2_paths(args.venv)
    env = env_for(venv, install, old={"PATH": "$PATH", "LD_LIBRARY_PATH": ""})
    for key, value in env.items():
        if key == "PATH":
            sys.stdout.write(f'export PATH={shlex.quote(str(venv / "bin"))}:"$PATH"\n')
        elif key == "LD_LIBRARY_PATH":
            sys.stdout.write(f"export LD_LIBRARY_PATH={shlex.quote(value)}"
                             '${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}\n')
        else:
            sys.stdout.write(f"export {key}={shlex.quote(value)}\n")
    return 0
