#!/usr/bin/env bash
# Set up ROS 2 (Kilted, from PyPI wheels) in a venv of its own, .venv-ros2, and build the
# interface packages that have no wheel (woosh_msgs, lowerbase_legged_msgs, tf2_msgs, nav2_msgs)
# into build/ros2/<hash of their definitions>/install. `make ros2` runs it; docs/ros2.md.
#
# A venv of its own because the wheels' bootstrapper (ros_wheels_bootstrapper.pth) re-executes
# every Python process of the venv it is installed in. Python 3.11 (the wheels are cp311, x86_64)
# from pyenv, or ROS2_PYTHON=/path/to/python3.11. Idempotent: pip runs again only when
# scripts/ros2-requirements.txt or pyproject.toml changed, the interfaces build only when their
# definitions (or the builder) changed.
#
# --optional (what `make test` runs): where ROS 2 cannot be set up here (not x86_64, no Python
# 3.11, no compiler, the package registry unreachable, or ROS2=0 in the environment), say why in
# one line and exit 0, so that tests/ros2 skip; once it can be set up, a failure is an error.
set -euo pipefail

cd "$(dirname "$0")/.."
VENV="${ROS2_VENV:-.venv-ros2}"
STAMP="$VENV/.lowerbase-ros2-installed"
OPTIONAL=0
[ "${1:-}" = --optional ] && OPTIONAL=1

fail() { echo "make ros2: $*" >&2; exit 1; }
# a reason this machine cannot have ROS 2: an error for `make ros2`, one line for `make test`
cannot() {
    if [ "$OPTIONAL" = 1 ]; then
        echo "make test: ROS 2 not set up, tests/ros2 will skip: $*" >&2
        exit 0
    fi
    fail "$*"
}

if [ "$OPTIONAL" = 1 ] && [ "${ROS2:-1}" = 0 ]; then
    cannot "ROS2=0 (make ros2 sets it up on its own)"
fi
[ "$(uname -m)" = x86_64 ] || cannot "the ROS 2 wheels are built for x86_64 only, this is $(uname -m)"
for tool in cmake ninja cc c++; do
    command -v "$tool" >/dev/null || cannot "$tool not found: apt-get install cmake ninja-build g++, then make ros2 again"
done

if [ -z "${ROS2_PYTHON:-}" ]; then
    ROS2_PYTHON="$({ ls -d "$(pyenv root 2>/dev/null)"/versions/3.11*/bin/python3.11 \
        "$HOME"/.pyenv/versions/3.11*/bin/python3.11 2>/dev/null; command -v python3.11; } \
        | sort -uV | tail -n 1)"
fi
[ -n "$ROS2_PYTHON" ] || cannot "no Python 3.11 found (pyenv install 3.11, or ROS2_PYTHON=/path/to/python3.11)"

# the index pip would use answers for ros-rclpy (15 s at most)
registry_reachable() {
    local index
    index="${PIP_INDEX_URL:-$("$ROS2_PYTHON" -m pip config get global.index-url 2>/dev/null || true)}"
    INDEX="${index:-https://pypi.org/simple}" "$ROS2_PYTHON" -c '
import os, sys, urllib.request
url = os.environ["INDEX"].rstrip("/") + "/ros-rclpy/"
try:
    urllib.request.urlopen(url, timeout=15).close()
except Exception as exc:
    sys.exit(f"{url}: {exc}")
'
}

want="$(cat scripts/ros2-requirements.txt pyproject.toml | sha256sum | cut -c1-16)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$want" ]; then
    if [ "$OPTIONAL" = 1 ] && ! why="$(registry_reachable 2>&1)"; then
        cannot "the package registry is unreachable ($why)"
    fi
    if [ ! -x "$VENV/bin/python" ]; then
        echo "make ros2: creating $VENV with $ROS2_PYTHON"
        "$ROS2_PYTHON" -m venv "$VENV"
    fi
    "$VENV/bin/python" -m pip install --quiet --upgrade pip 2>&1 | grep -v '^WARNING: Location' || true
    # one resolver run for the wheels and lowerbase (its numpy must suit both)
    "$VENV/bin/python" -m pip install --quiet -r scripts/ros2-requirements.txt -e . \
        2>&1 | grep -v '^WARNING: Location' || true
    "$VENV/bin/python" -c 'import rclpy, rosidl_adapter, lowerbase' \
        || fail "pip did not install everything (see above); make ros2 again once the registry is reachable"
    echo "$want" > "$STAMP"
fi

"$VENV/bin/python" -m lowerbase.ros2.interfaces
