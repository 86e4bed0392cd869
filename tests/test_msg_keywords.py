"""ROS messages are built with keyword fields only: the faces share their builders between
rospy (genpy takes positional fields too) and rclpy (keywords only; its Header has no ``seq``).
A positional ``Header(0, stamp, frame)`` in driver/ros_io.py passed every ROS 1 test and left
``driver --ros2`` without /odom; tests/ros2 needs the ROS 2 env, which CI does not build, so
this check runs everywhere."""

from __future__ import annotations

import ast

from tests.conftest import ROOT

KINDS = (".msg", ".srv")  #: modules whose classes are messages (``rclpy.action`` is not)


def positional_message_calls(source: str) -> list[tuple[int, str]]:
    """(line, class) of every call with positional arguments of a class imported from a
    ``*.msg`` / ``*.srv`` module."""
    tree = ast.parse(source)
    names = {a.asname or a.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
             and node.module and node.module.endswith(KINDS) for a in node.names}
    return [(node.lineno, node.func.id) for node in ast.walk(tree)
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id in names and node.args]


def test_the_check_finds_a_positional_message() -> None:
    src = ("from std_msgs.msg import Header\nfrom geometry_msgs.msg import Vector3 as V\n"
           "h = Header(0, stamp, 'odom')\nv = V(x=1.0)\nw = V(1.0, 2.0, 3.0)\n")
    assert positional_message_calls(src) == [(3, "Header"), (5, "V")]


def test_no_message_is_built_with_positional_fields() -> None:
    found = [f"{path.relative_to(ROOT)}:{line}: {name}(...)"
             for path in sorted((ROOT / "lowerbase").rglob("*.py"))
             for line, name in positional_message_calls(path.read_text(encoding="utf-8"))]
    assert not found, "give message fields by keyword (ROS 2 takes no positional ones):\n" \
        + "\n".join(found)
