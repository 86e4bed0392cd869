"""``lowerbase robot --mcap FILE`` on a real ROS master: the recorder child writes the robot's
ROS topics and the bus's frames into one MCAP, finished at Ctrl-C. Checked against what an
independent subscriber (the driver tests' probe node) saw on the same topics, decoded with
mcap-ros1-support; the frames with the codec."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros1.decoder import DecoderFactory

from lowerbase.protocol.codec import default_codec
from tests.driver.conftest import ros_master, woosh_msgs_build  # noqa: F401
from tests.driver.test_node_ros import PROBE, Probe
from tests.robot.test_robot_ros import TOPICS, Robot, _x


@pytest.mark.ros
@pytest.mark.process
def test_robot_mcap_records_topics_and_frames(ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
    path = tmp_path / "robot.mcap"
    robot = Robot(env, tmp_path / "logs", "--without", "navigation", "--without", "tasks",
                  "--mcap", str(path))
    probe = None
    try:
        robot.wait_for("ready on ROS master")
        assert len(robot.children()) == 4  # world, recorder, emulate, driver
        script = tmp_path / "probe.py"
        script.write_text(PROBE)
        probe = Probe(script, ros_master.env, TOPICS)
        start = probe.wait_for(lambda s: all(s[t]["count"] >= 1 for t in TOPICS), 60.0,
                               "odom, scan and amcl_pose")
        probe.ask(op="publish", topic="/base_cmd_vel", type="geometry_msgs/Twist",
                  fields={"linear": {"x": 0.3}, "angular": {"z": 0.0}}, rate=20, duration=2.0)
        seen = probe.wait_for(lambda s: _x(s, "/odom") > _x(start, "/odom") + 0.3, 20.0,
                              "/odom moving forward")
    finally:
        if probe is not None:
            probe.close()
        code, out, err = robot.ctrl_c()
    assert code == 0 and "lowerbase robot: stopped" in out, err
    assert "Traceback" not in (tmp_path / "logs" / "recorder.log").read_text()

    decoded: dict[str, dict[int, Any]] = {"/odom": {}, "/scan": {}}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        for _, channel, _, msg in reader.iter_decoded_messages(topics=list(decoded)):
            decoded[channel.topic][msg.header.seq] = msg
    assert summary is not None
    types = {c.topic: (summary.schemas[c.schema_id].name, c.metadata.get("md5sum"))
             for c in summary.channels.values()}
    assert types["/odom"] == ("nav_msgs/Odometry", "cd5e73d190d741a2f92e81eda573aca7")
    assert types["/scan"][0] == "sensor_msgs/LaserScan"
    assert {"/odom_raw", "/imu/data_raw", "/tf", "/map", "/can/frames"} <= set(types)
    # the velocity commands driver_base obeys (navigation's, here the probe's 2 s at 20 Hz)
    assert types["/base_cmd_vel"] == ("geometry_msgs/Twist", "9f195f881246fdfa2798d1d3eebca84a")
    with path.open("rb") as f:
        commands = [m for *_, m in make_reader(f, decoder_factories=[DecoderFactory()])
                    .iter_decoded_messages(topics=["/base_cmd_vel"])]
    assert len(commands) >= 20 and {(m.linear.x, m.angular.z) for m in commands} == {(0.3, 0.0)}
    # the message the probe saw last is in the file, the same
    for topic in ("/odom", "/scan"):
        theirs = seen[topic]["msg"]
        ours = decoded[topic][theirs["header"]["seq"]]
        assert ours.header.stamp.secs + 1e-9 * ours.header.stamp.nsecs == \
            theirs["header"]["stamp"]
    theirs = seen["/odom"]["msg"]["pose"]["pose"]["position"]
    ours = decoded["/odom"][seen["/odom"]["msg"]["header"]["seq"]].pose.pose.position
    assert (ours.x, ours.y) == (theirs["x"], theirs["y"])
    assert max(m.pose.pose.position.x for m in decoded["/odom"].values()) > \
        _x(start, "/odom") + 0.3
    assert len(decoded["/scan"]) > 10
    assert decoded["/scan"][max(decoded["/scan"])].header.frame_id == "base_link"
    # the bus: every frame raw, and each catalog frame's signals next to it
    codec = default_codec()
    wheel = codec.message("WheelFeedback").frame_id
    with path.open("rb") as f:
        raw = [m for *_, m in make_reader(f, decoder_factories=[DecoderFactory()])
               .iter_decoded_messages(topics=["/can/frames"])]
    assert len(raw) > 100 and {"/can/decoded/WheelFeedback", "/can/decoded/MotionCommand"} \
        <= set(types)
    counts = {c.topic: summary.statistics.channel_message_counts[i]  # type: ignore[union-attr]
              for i, c in summary.channels.items()}
    assert counts["/can/decoded/WheelFeedback"] == sum(1 for m in raw if m.id == wheel) > 10
