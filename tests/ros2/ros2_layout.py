"""Run in the ROS 2 venv: import the named interfaces, fill every field with a value, serialize,
deserialize, and print (JSON) each type's fields, the serialized size and whether it round-trips.

Usage: ros2_layout.py pkg/msg/Type ...  (actions: pkg/action/Type prints Goal, Result, Feedback)
"""

from __future__ import annotations

import importlib
import json
import sys
from typing import Any

from rclpy.serialization import deserialize_message, serialize_message


def fill(msg: Any, depth: int = 0) -> Any:
    """Give every field a distinctive value (nested messages recursively)."""
    for i, (name, kind) in enumerate(msg.get_fields_and_field_types().items()):
        value = getattr(msg, name)
        if kind in ("float", "double"):
            setattr(msg, name, 1.5 + i)
        elif kind == "boolean":
            setattr(msg, name, True)
        elif kind.startswith(("int", "uint")) and "[" not in kind and "<" not in kind:
            setattr(msg, name, i + 1)
        elif kind == "string":
            setattr(msg, name, f"f{i}")
        elif kind.startswith("sequence<") and "/" in kind and depth < 2:
            cls = _class_of(kind[len("sequence<"):-1])
            setattr(msg, name, [fill(cls(), depth + 1), fill(cls(), depth + 1)])
        elif hasattr(value, "get_fields_and_field_types") and depth < 3:
            fill(value, depth + 1)
    return msg


def _class_of(type_name: str) -> Any:
    pkg, name = type_name.split("/")
    for kind in ("msg", "action", "srv"):
        try:
            return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
        except (ImportError, AttributeError):
            continue
    raise LookupError(type_name)


def describe(cls: Any) -> dict[str, Any]:
    msg = fill(cls())
    data = serialize_message(msg)
    back = deserialize_message(data, cls)
    return {"fields": list(cls.get_fields_and_field_types().items()), "size": len(data),
            "roundtrip": back == msg}


def main() -> None:
    out: dict[str, Any] = {}
    for spec in sys.argv[1:]:
        pkg, kind, name = spec.split("/")
        module = importlib.import_module(f"{pkg}.{kind}")
        cls = getattr(module, name)
        if kind == "action":
            for part in ("Goal", "Result", "Feedback"):
                out[f"{spec}_{part}"] = describe(getattr(cls, part))
        elif kind == "srv":
            for part in ("Request", "Response"):
                out[f"{spec}_{part}"] = describe(getattr(cls, part))
        else:
            out[spec] = describe(cls)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
