"""The MCAP of a simulated drive read back with the mcap reader and rosbags, against the
SimLoop's own state, genpy's md5sums and the rospy node's message bytes."""

from __future__ import annotations

import hashlib
import json
import math
import os
import subprocess
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from lowerbase.protocol.codec import default_codec
from lowerbase.recording.messages import to_ns
from lowerbase.recording.ros1_types import md5_of_definition, ros1_types
from tests.recording.conftest import Recorded, record_drive

DRIVER_TOPICS = {"/odom": "nav_msgs/Odometry", "/odom_raw": "nav_msgs/Odometry",
                 "/imu/data_raw": "sensor_msgs/Imu", "/battery": "woosh_msgs/Battery",
                 "/driver_base/bms": "woosh_msgs/BMS", "/status_code": "std_msgs/UInt64",
                 "/tf": "tf2_msgs/TFMessage", "/ground_truth/odom": "nav_msgs/Odometry",
                 "/can/frames": "can_msgs/Frame"}


def read_all(path: Path) -> dict[str, list[tuple[Any, Any, Any]]]:
    by_topic: dict[str, list[tuple[Any, Any, Any]]] = defaultdict(list)
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            by_topic[channel.topic].append((schema, channel, message))
    return by_topic


def yaw_of(q: Any) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def test_topics_types_and_encodings(recorded: Recorded) -> None:
    got = read_all(recorded.path)
    for topic, type_name in DRIVER_TOPICS.items():
        assert got[topic], topic
        schema, channel, _ = got[topic][0]
        assert (schema.name, schema.encoding, channel.message_encoding) == (
            type_name, "ros1msg", "ros1")
    # the wheel odometry at 50 Hz over the 5 s drive, battery once per 1 s BMS burst
    assert 0.9 * 50 * 4 < len(got["/odom"]) <= 50 * 5
    assert 3 <= len(got["/battery"]) <= 6
    assert {k: len(v) for k, v in got.items()} == recorded.counts


def test_odom_and_truth_equal_the_simloop_state(recorded: Recorded) -> None:
    types = ros1_types()
    got = read_all(recorded.path)
    odom = [types.deserialize(m.data, "nav_msgs/Odometry") for _, _, m in got["/odom"]]
    raw = [types.deserialize(m.data, "nav_msgs/Odometry") for _, _, m in got["/odom_raw"]]
    truth = [types.deserialize(m.data, "nav_msgs/Odometry")
             for _, _, m in got["/ground_truth/odom"]]
    times = [m.log_time for _, _, m in got["/odom"]]
    assert len(odom) == len(raw) == len(truth) == len(recorded.states)
    assert max(s[2][0] for s in recorded.states) > 1.0  # it drove
    for i, (t, ekf, wheel, tr) in enumerate(recorded.states):
        assert times[i] == to_ns(t)
        o = odom[i]
        assert (o.header.stamp.sec * 10**9 + o.header.stamp.nanosec) == times[i]
        assert o.header.seq == i + 1 and o.header.frame_id == "odom"
        assert o.child_frame_id == "base_link"
        p = o.pose.pose.position
        assert (p.x, p.y) == ekf[:2]
        assert yaw_of(o.pose.pose.orientation) == pytest.approx(ekf[2], abs=1e-12)
        r = raw[i].pose.pose.position
        assert (r.x, r.y) == wheel[:2]
        g = truth[i]
        assert (g.pose.pose.position.x, g.pose.pose.position.y) == tr[:2]
        assert yaw_of(g.pose.pose.orientation) == pytest.approx(
            math.remainder(tr[2], math.tau), abs=1e-12)
        assert (g.twist.twist.linear.x, g.twist.twist.angular.z) == tr[3:]
    tf = types.deserialize(got["/tf"][-1][2].data, "tf2_msgs/TFMessage").transforms[0]
    assert (tf.header.frame_id, tf.child_frame_id) == ("odom", "base_link")
    assert tf.transform.translation.x == odom[-1].pose.pose.position.x


def test_frames_and_decoded_signals(recorded: Recorded) -> None:
    types = ros1_types()
    got = read_all(recorded.path)
    frames = [(m.log_time, types.deserialize(m.data, "can_msgs/Frame"))
              for _, _, m in got["/can/frames"]]
    assert len(frames) == len(recorded.frames)
    codec = default_codec()
    decoded: dict[str, list[Any]] = defaultdict(list)
    for (log_time, f), (t, frame_id, data) in zip(frames, recorded.frames, strict=True):
        assert log_time == to_ns(t) and f.id == frame_id and f.dlc == len(data)
        assert bytes(f.data[: f.dlc]) == data
        name, values = codec.decode(frame_id, data, strict=False)
        decoded[name].append(values)
    for name, values in decoded.items():
        topic = got[f"/can/decoded/{name}"]
        schema, channel, _ = topic[0]
        assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
        assert set(json.loads(schema.data)["properties"]) >= set(values[0])
        assert [json.loads(m.data) for _, _, m in topic] == values


def test_schemas_md5_equal_genpy(recorded: Recorded) -> None:
    genpy_classes = pytest.importorskip("woosh_msgs.msg")
    import nav_msgs.msg
    import sensor_msgs.msg
    import std_msgs.msg
    import tf2_msgs.msg

    classes = {"woosh_msgs/Battery": genpy_classes.Battery, "woosh_msgs/BMS": genpy_classes.BMS,
               "nav_msgs/Odometry": nav_msgs.msg.Odometry, "sensor_msgs/Imu": sensor_msgs.msg.Imu,
               "std_msgs/UInt64": std_msgs.msg.UInt64, "tf2_msgs/TFMessage": tf2_msgs.msg.TFMessage}
    seen = set()
    for topic, items in read_all(recorded.path).items():
        schema, channel, _ = items[0]
        if schema.name in classes:
            cls = classes[schema.name]
            assert md5_of_definition(schema.name, schema.data.decode()) == cls._md5sum, topic
            assert channel.metadata["md5sum"] == cls._md5sum
            seen.add(schema.name)
    assert seen == set(classes)
    for name in ("BMS", "Battery", "Charge", "IOModule", "Information", "LED", "Parameter",
                 "RfRemoteController", "RobotStatus", "StepControl"):
        assert ros1_types().schema(f"woosh_msgs/{name}").md5sum == getattr(
            genpy_classes, name)._md5sum, name
    try:  # can_msgs, where ros_canopen is installed
        import can_msgs.msg
    except ImportError:
        assert ros1_types().schema("can_msgs/Frame").md5sum == "64ae5cebf967dc6aae4e78f5683a5b25"
    else:
        assert ros1_types().schema("can_msgs/Frame").md5sum == can_msgs.msg.Frame._md5sum


def test_bytes_equal_the_rospy_node_messages(tmp_path: Path) -> None:
    pytest.importorskip("rospy")
    pytest.importorskip("woosh_msgs.msg")
    pytest.importorskip("tf2_msgs.msg")
    run = record_drive(tmp_path / "node.mcap", with_ros_io=True)
    got = read_all(run.path)
    ours: dict[str, list[bytes]] = {t: [m.data for _, _, m in got[t]] for t in got}
    theirs: dict[str, list[bytes]] = defaultdict(list)
    for topic, data in run.ros_io:
        theirs[topic].append(data)
    assert set(theirs) == {"/odom", "/odom_raw", "/tf", "/imu/data_raw", "/status_code"}
    for topic, data in theirs.items():
        assert ours[topic] == data, topic


def test_battery_fields_as_the_driver_has_them(recorded: Recorded) -> None:
    types = ros1_types()
    got = read_all(recorded.path)
    b = types.deserialize(got["/battery"][-1][2].data, "woosh_msgs/Battery")
    bms = types.deserialize(got["/driver_base/bms"][-1][2].data, "woosh_msgs/BMS")
    assert 0 < b.batteryPercentage <= 100 and 40 < b.batteryVoltage < 60
    assert bms.voltageTotal == pytest.approx(b.batteryVoltage, rel=1e-6)
    assert b.header.seq == len(got["/battery"])


ROS_FREE = """
import sys
for name in ("rospy", "genpy", "genmsg", "roslib", "std_msgs", "nav_msgs", "sensor_msgs",
             "geometry_msgs", "tf2_msgs", "tf2_ros", "woosh_msgs", "rosbag"):
    sys.modules[name] = None  # import raises ImportError
from pathlib import Path
from tests.recording.conftest import record_drive
record_drive(Path(sys.argv[1]))
assert not any(m.split(".")[0] in ("rospy", "genpy") for m, v in sys.modules.items() if v)
"""


def test_ros_free_run_writes_the_same_file(recorded: Recorded, tmp_path: Path) -> None:
    out = tmp_path / "noros.mcap"
    root = Path(__file__).resolve().parents[2]
    subprocess.run([sys.executable, "-c", ROS_FREE, str(out)], check=True, cwd=root,
                   env={**os.environ, "PYTHONPATH": str(root)}, timeout=120)
    ours, theirs = out.read_bytes(), recorded.path.read_bytes()
    # a digest, not the bytes: pytest's diff of two large byte strings takes minutes
    first = next((i for i, (a, b) in enumerate(zip(ours, theirs, strict=False)) if a != b),
                 min(len(ours), len(theirs)))
    assert hashlib.sha256(ours).hexdigest() == hashlib.sha256(theirs).hexdigest(), (
        f"sizes {len(ours)} and {len(theirs)}, first difference at byte {first}")
