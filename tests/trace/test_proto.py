"""The seed's messages: the checked-in generated code is what protoc makes of trace.proto, the
definitions are the seed's (field numbers, labels, types, enum values), and the wire bytes are
protobuf's (checked against hand-computed encodings and a freshly protoc-built module)."""

from __future__ import annotations

import math
from pathlib import Path
from types import ModuleType

import pytest
from google.protobuf.descriptor import FieldDescriptor as F

from lowerbase.trace import messages as m
from lowerbase.trace.proto import trace_pb2
from lowerbase.trace.protogen import PROTO, compile_proto


def _label(f: F) -> str:
    return "required" if f.is_required else "repeated" if f.is_repeated else "optional"

# (name, number, label, type) as shared/seeds/001 writes them
SEED = {
    "GTracePoint": [("x", 1, "required", F.TYPE_DOUBLE), ("y", 2, "required", F.TYPE_DOUBLE),
                    ("angle", 3, "required", F.TYPE_DOUBLE),
                    ("speed", 4, "optional", F.TYPE_INT32),
                    ("starter", 5, "optional", F.TYPE_INT32)],
    "GTraceSeg": [("first", 1, "required", F.TYPE_MESSAGE),
                  ("second", 2, "required", F.TYPE_MESSAGE),
                  ("finished", 3, "required", F.TYPE_DOUBLE)],
    "GTraceList": [("lists", 1, "repeated", F.TYPE_MESSAGE), ("map", 2, "required", F.TYPE_BYTES),
                   ("status", 3, "optional", F.TYPE_ENUM)],
}


@pytest.fixture(scope="module")
def fresh(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, ModuleType]:
    """trace.proto compiled now by protoc; its classes built in a private descriptor pool
    (the default one already holds the checked-in file)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    out = tmp_path_factory.mktemp("protoc")
    py, _ = compile_proto(out)
    pool = descriptor_pool.DescriptorPool()
    fdp = descriptor_pb2.FileDescriptorProto.FromString(
        trace_pb2.DESCRIPTOR.serialized_pb)
    text = py.read_text()
    start = text.index("AddSerializedFile(") + len("AddSerializedFile(")
    import ast
    serialized = ast.literal_eval(text[start:text.index(")\n", start)])  # protoc's literal
    fresh_fdp = descriptor_pb2.FileDescriptorProto.FromString(serialized)
    pool.Add(fresh_fdp)
    module = ModuleType("fresh")
    for name in SEED | {"GLaserScan": 0, "RobotPose2D": 0, "GRobotSpeedControl": 0}:
        desc = pool.FindMessageTypeByName(f"lowerbase.trace.{name}")
        setattr(module, name, message_factory.GetMessageClass(desc))
    module.fdp = fresh_fdp  # type: ignore[attr-defined]
    module.checked_in = fdp  # type: ignore[attr-defined]
    return py, module


def test_checked_in_code_is_what_protoc_generates(fresh: tuple[Path, ModuleType]) -> None:
    py, module = fresh
    assert module.fdp == module.checked_in, "run: python -m lowerbase.trace.protogen"
    assert module.fdp.name == "lowerbase/trace/proto/trace.proto"
    checked = Path(trace_pb2.__file__)
    # the same protoc version writes the same text (the header names the gencode version)
    assert py.read_text().splitlines()[4:] == checked.read_text().splitlines()[4:]
    assert PROTO.is_file()


@pytest.mark.parametrize("name", sorted(SEED))
def test_fields_are_the_seeds(name: str) -> None:
    desc = getattr(trace_pb2, name).DESCRIPTOR
    got = [(f.name, f.number, _label(f), f.type) for f in desc.fields]
    assert got == SEED[name]


def test_execute_status_values_and_syntax() -> None:
    enum = trace_pb2.GTraceList.DESCRIPTOR.enum_types_by_name["ExecuteStatus"]
    assert {v.name: v.number for v in enum.values} == {
        "EXECUTE_STATUS_IDLE": 1, "EXECUTE_STATUS_RUNNING": 2, "EXECUTE_STATUS_BLOCKED": 3,
        "EXECUTE_STATUS_FINISHED": 4}
    assert (m.IDLE, m.RUNNING, m.BLOCKED, m.FINISHED) == (1, 2, 3, 4)
    from google.protobuf import descriptor_pb2
    fdp = descriptor_pb2.FileDescriptorProto.FromString(trace_pb2.DESCRIPTOR.serialized_pb)
    assert fdp.syntax in ("", "proto2")  # protoc leaves proto2's syntax out


def _segment(lst: trace_pb2.GTraceList, a: tuple[float, float], b: tuple[float, float],
             finished: float = 0.0) -> None:
    s = lst.lists.add()
    s.first.x, s.first.y, s.first.angle = a[0], a[1], 0.0
    s.second.x, s.second.y, s.second.angle = b[0], b[1], 0.0
    s.finished = finished


def test_wire_bytes_by_hand() -> None:
    """A point's bytes computed by hand from the protobuf encoding rules."""
    p = trace_pb2.GTracePoint(x=1.0, y=-2.0, angle=0.5, speed=500, starter=1)
    import struct
    want = (b"\x09" + struct.pack("<d", 1.0) + b"\x11" + struct.pack("<d", -2.0)
            + b"\x19" + struct.pack("<d", 0.5) + b"\x20\xf4\x03" + b"\x28\x01")
    assert p.SerializeToString() == want
    lst = trace_pb2.GTraceList(map=b"warehouse", status=m.BLOCKED)
    assert lst.SerializeToString() == b"\x12\x09warehouse\x18\x03"


def test_round_trip_against_the_fresh_protoc_classes(fresh: tuple[Path, ModuleType]) -> None:
    _, mod = fresh
    lst = trace_pb2.GTraceList(map=b"warehouse")
    _segment(lst, (1.0, 2.0), (3.5, 2.0), 0.25)
    lst.lists[0].first.speed = 500
    lst.lists[0].first.starter = 1
    data = lst.SerializeToString()
    other = mod.GTraceList.FromString(data)
    assert other.lists[0].second.x == 3.5 and other.lists[0].finished == 0.25
    assert other.lists[0].first.speed == 500 and not other.HasField("status")
    other.status = 2
    back = trace_pb2.GTraceList.FromString(other.SerializeToString())
    assert back.status == m.RUNNING and back.map == b"warehouse"
    scan = mod.GLaserScan(stamp=1.5, frame_id="base_link", angle_min=-1.0, angle_max=1.0,
                          angle_increment=0.5, time_increment=0.0, scan_time=0.1,
                          range_min=0.05, range_max=20.0, ranges=[1.0, math.inf, 2.0])
    got = trace_pb2.GLaserScan.FromString(scan.SerializeToString())
    assert list(got.ranges) == [1.0, math.inf, 2.0] and got.frame_id == "base_link"


def test_status_is_optional_in_requests_required_in_reports() -> None:
    lst = trace_pb2.GTraceList(map=b"")
    _segment(lst, (0, 0), (1, 0))
    assert lst.IsInitialized() and not lst.HasField("status")  # a request without status
    route = m.check_route(lst)
    rep = m.report(route, m.RUNNING, [0.5])
    assert rep.HasField("status") and rep.status == m.RUNNING and rep.lists[0].finished == 0.5
    assert not lst.HasField("status")  # the received list is not touched


@pytest.mark.parametrize("data, match", [
    (b"", "required field.*map"),
    (b"\x0a\x00\x12\x00", "required field.*lists\\[0\\].first"),
    (b"\xff\xff\xff", "undecodable"),
])
def test_decode_refuses_bad_bytes_with_a_clear_error(data: bytes, match: str) -> None:
    with pytest.raises(m.TraceError, match=match):
        m.decode("GTraceList", data, trace_pb2.GTraceList)


def test_decode_refuses_the_wrong_type() -> None:
    data = trace_pb2.RobotPose2D(stamp=0, x=0, y=0, theta=0).SerializeToString()
    with pytest.raises(m.TraceError, match="send GTraceList"):
        m.decode("RobotPose2D", data, trace_pb2.GTraceList)


def test_the_envelope_knows_the_four_types() -> None:
    assert set(m.TYPES) == {"GTraceList", "GLaserScan", "RobotPose2D", "GRobotSpeedControl"}
    assert m.encode(trace_pb2.GTraceList(map=b"x")) == ("GTraceList", b"\x12\x01x")
