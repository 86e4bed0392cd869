"""ROS1 message types without a ROS install: definitions, md5sums and serialisation.

Built on rosbags' typestore (its ROS1 Noetic store carries std_msgs, geometry_msgs, nav_msgs,
sensor_msgs, ...), to which lowerbase adds:

* ``woosh_msgs`` from the definitions shipped in ``lowerbase/driver/msg/woosh_msgs/`` (the
  same files genpy generates the driver's classes from);
* ``tf2_msgs/TFMessage`` and ``can_msgs/Frame``, with their standard definitions.

rosbags' parser only takes UPPER_SNAKE constant names; woosh_msgs has camelCase ones
(``uint8 manualMode = 0``), which ROS1 allows. Constant lines are therefore read here and
handed to the typestore as constants, so the md5sum is ROS1's (tests compare it with genpy's).

:func:`schema` is what an MCAP ``ros1msg`` schema (and a rosbag connection header) carries:
the type's own definition followed by every dependency after a line of 80 ``=`` and
``MSG: pkg/Type``, as rosbag and mcap-ros1-support write it.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError

WOOSH_DIR = Path(__file__).resolve().parents[1] / "driver" / "msg" / "woosh_msgs"

#: standard definitions of the types rosbags' ROS1 store lacks
EXTRA_DEFINITIONS: dict[str, str] = {
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    # can_msgs (ros_canopen): a classic CAN frame as socketcan_bridge publishes it
    "can_msgs/Frame": (
        "Header header\n"
        "uint32 id\n"
        "bool is_rtr\n"
        "bool is_extended\n"
        "bool is_error\n"
        "uint8 dlc\n"
        "uint8[8] data\n"
    ),
}

SEPARATOR = "=" * 80 + "\n"
_CONSTANT = re.compile(r"^\s*([A-Za-z0-9_]+)\s+([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.*?)\s*$")
_INT_TYPES = {"bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32",
              "int64", "uint64"}


def ros2_name(name: str) -> str:
    """``pkg/Type`` -> rosbags' ``pkg/msg/Type`` (unchanged if it already is)."""
    pkg, _, typ = name.rpartition("/")
    return name if pkg.endswith("/msg") else f"{pkg}/msg/{typ}"


def ros1_name(name: str) -> str:
    """rosbags' ``pkg/msg/Type`` -> ``pkg/Type``."""
    return name.replace("/msg/", "/")


def _split_constants(text: str) -> tuple[str, list[tuple[str, str, Any]]]:
    """(the text without its constant lines, [(name, type, value)])."""
    lines, constants = [], []
    for line in text.splitlines():
        body = line.split("#", 1)[0]
        m = _CONSTANT.match(body)
        if m is None:
            lines.append(line)
            continue
        typ, name, raw = m.groups()
        if typ == "string":
            value: Any = line.split("=", 1)[1].strip()  # strings keep '#' and take the rest
        elif typ in _INT_TYPES:
            value = int(raw, 0)
        else:
            value = float(raw)
        constants.append((name, typ, value))
    return "\n".join(lines) + "\n", constants


def parse_definition(name: str, text: str) -> dict[str, Any]:
    """rosbags Typesdict of one message definition ``text`` named ``pkg/Type``.

    ``text`` may be a concatenated definition (with ``MSG:`` sections, as in an MCAP schema
    or a bag's connection header); every section's types are returned."""
    from rosbags.typesys import get_types_from_msg
    from rosbags.typesys.base import TypesysError

    sections = text.split(SEPARATOR)
    found: dict[str, Any] = {}
    for i, section in enumerate(sections):
        own = name
        if i:
            head, _, section = section.partition("\n")
            if not head.startswith("MSG: "):
                raise ConfigError(f"{name}: bad definition section header {head!r}")
            own = head[5:].strip()
        stripped, constants = _split_constants(section)
        try:
            types = get_types_from_msg(stripped, ros2_name(own))
        except TypesysError as exc:
            raise ConfigError(f"{own}: cannot parse its message definition: {exc}") from None
        for key, (consts, fields) in types.items():
            found[key] = ([*consts, *constants] if key == ros2_name(own) else consts, fields)
    return found


@dataclass(frozen=True)
class Schema:
    name: str  #: ``pkg/Type``
    text: str  #: full concatenated definition
    md5sum: str


class Ros1Types:
    """A typestore with ROS1 Noetic's types, woosh_msgs and the extras; see the module doc."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS1_NOETIC)
        self._own_text: dict[str, str] = {}
        for name, text in EXTRA_DEFINITIONS.items():
            self.register(name, text)
        for path in sorted(WOOSH_DIR.glob("*.msg")):
            self.register(f"woosh_msgs/{path.stem}", path.read_text(encoding="utf-8"))
        self._schemas: dict[str, Schema] = {}

    def register(self, name: str, text: str) -> None:
        """Add type ``pkg/Type`` from its .msg ``text`` (its dependencies must be known)."""
        self.store.register(parse_definition(name, text))
        self._own_text[ros1_name(ros2_name(name))] = text

    def schema(self, name: str) -> Schema:
        """The full definition and md5sum of ``pkg/Type``."""
        name = ros1_name(ros2_name(name))
        cached = self._schemas.get(name)
        if cached is not None:
            return cached
        try:
            text, md5 = self.store.generate_msgdef(ros2_name(name))
        except Exception as exc:  # rosbags raises its own TypesysError or a KeyError
            raise ConfigError(f"unknown ROS1 message type {name}: {exc}") from None
        own = self._own_text.get(name)
        if own is not None:  # the source text, with its comments and constants
            _, sep, deps = text.partition(SEPARATOR)
            text = own.rstrip("\n") + "\n" + (sep + deps if sep else "")
        schema = Schema(name, text, md5)
        self._schemas[name] = schema
        return schema

    def message(self, name: str, **fields: Any) -> Any:
        """A new message object of ``pkg/Type``."""
        return self.store.types[ros2_name(name)](**fields)

    def cls(self, name: str) -> Any:
        return self.store.types[ros2_name(name)]

    def serialize(self, msg: Any) -> bytes:
        return bytes(self.store.serialize_ros1(msg, msg.__msgtype__))

    def deserialize(self, data: bytes, name: str) -> Any:
        return self.store.deserialize_ros1(data, ros2_name(name))


@functools.lru_cache(maxsize=1)
def ros1_types() -> Ros1Types:
    """The shared :class:`Ros1Types` (building it parses every definition once)."""
    return Ros1Types()


def md5_of_definition(name: str, text: str) -> str:
    """ROS1 md5sum of type ``pkg/Type`` from its full (concatenated) definition ``text``."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.EMPTY)
    store.register(parse_definition(name, text))
    try:
        return store.generate_msgdef(ros2_name(name))[1]
    except Exception as exc:
        raise ConfigError(f"{name}: incomplete message definition: {exc}") from None
