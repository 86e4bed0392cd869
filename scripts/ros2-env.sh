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
set -euo pipefail

cd "$(dirname "$0")/.."
VENV="${ROS2_VENV:-.venv-ros2}"
STAMP="$VENV/.lowerbase-ros2-installed"

fail() { echo "make ros2: $*" >&2; exit 1; }

[ "$(uname -m)" = x86_64 ] || fail "the ROS 2 wheels are built for x86_64 only, this is $(uname -m)"
for tool in cmake ninja cc c++; do
    command -v "$tool" >/dev/null || fail "$tool not found: apt-get install cmake ninja-build g++, then make ros2 again"
done

if [ -z "${ROS2_PYTHON:-}" ]; then
    ROS2_PYTHON="$({ ls -d "$(pyenv root 2>/dev/null)"/versions/3.11*/bin/python3.11 \
        "$HOME"/.pyenv/versions/3.11*/bin/python3.11 2>/dev/null; command -v python3.11; } \
        | sort -uV | tail -n 1)"
fi
[ -n "$ROS2_PYTHON" ] || fail "no Python 3.11 found (pyenv install 3.11, or ROS2_PYTHON=/path/to/python3.11)"

want="$(cat scripts/ros2-requirements.txt pyproject.toml | sha256sum | cut -c1-16)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$want" ]; then
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
