"""lowerbase_msgs/Protobuf as msggen generates it: the md5sum (pinned, and as genmsg and the
ROS tools compute it), the fields, and a GTraceList through its wire format."""

from __future__ import annotations

import hashlib
import io
import os
import shutil
import subprocess
from pathlib import Path
from types import ModuleType

import pytest

from lowerbase.driver import msggen
from lowerbase.trace import messages as m
from tests.trace.routes import route
from tests.trace.trace_ros import lowerbase_msgs, trace_build  # noqa: F401

#: ROS1 refuses a connection when the two ends' md5sums differ: changing the .msg breaks users
PROTOBUF_MD5 = "69618d2208b0e50e53fd0c4f85a72455"
SOURCE = msggen.TRACE.source / "Protobuf.msg"


def test_md5sum_is_pinned_and_is_genmsgs(lowerbase_msgs: ModuleType) -> None:  # noqa: F811
    import genmsg
    from genmsg.msg_loader import load_msg_from_file

    cls = lowerbase_msgs.Protobuf
    assert cls._type == "lowerbase_msgs/Protobuf"
    assert cls._md5sum == PROTOBUF_MD5
    ctx = genmsg.MsgContext.create_default()
    spec = load_msg_from_file(ctx, str(SOURCE), "lowerbase_msgs/Protobuf")
    assert genmsg.compute_md5(ctx, spec) == PROTOBUF_MD5
    # ROS1's md5 of builtin fields: the comment-free "type name" lines
    assert hashlib.md5(b"string type\nuint8[] data").hexdigest() == PROTOBUF_MD5
    assert list(zip(cls.__slots__, cls._slot_types, strict=True)) == [
        ("type", "string"), ("data", "uint8[]")]


def test_a_gtracelist_crosses_the_envelope(lowerbase_msgs: ModuleType) -> None:  # noqa: F811
    sent = route([1.0, 2.0, 3.5], starters=[0], speed=400)
    type_name, data = m.encode(sent)
    buf = io.BytesIO()
    lowerbase_msgs.Protobuf(type=type_name, data=data).serialize(buf)
    wire = buf.getvalue()
    # ROS1 serialization: uint32 length + UTF-8, then uint32 length + the bytes
    assert wire == (len(b"GTraceList").to_bytes(4, "little") + b"GTraceList"
                    + len(data).to_bytes(4, "little") + data)
    back = lowerbase_msgs.Protobuf().deserialize(wire)
    assert m.decode(back.type, back.data, m.GTraceList) == sent


def test_the_ros_tools_find_it(trace_build: Path) -> None:  # noqa: F811
    rosmsg = shutil.which("rosmsg")
    if rosmsg is None:
        pytest.skip("rosmsg not installed")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["ROS_PACKAGE_PATH"] = str(trace_build / "share")
    env["ROS_HOME"] = str(trace_build / "ros_home")
    out = subprocess.run([rosmsg, "md5", "lowerbase_msgs/Protobuf"], env=env,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == PROTOBUF_MD5
