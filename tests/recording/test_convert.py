"""MCAP -> .bag read back with Debian's rosbag and with rosbags; .bag -> .mcap round trip;
the `lowerbase mcap` commands and their errors."""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from pathlib import Path

import pytest
from mcap.reader import make_reader

from lowerbase.cli import main
from lowerbase.errors import ConfigError
from lowerbase.recording.convert import bag_to_mcap, mcap_to_bag
from lowerbase.recording.messages import to_ns
from tests.recording.conftest import Recorded


def mcap_messages(path: Path) -> list[tuple[str, int, bytes]]:
    with path.open("rb") as f:
        return [(c.topic, m.log_time, m.data)
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


def test_to_bag_read_with_rosbags(recorded: Recorded, tmp_path: Path) -> None:
    from rosbags.rosbag1 import Reader

    bag = tmp_path / "drive.bag"
    done = mcap_to_bag(recorded.path, bag)
    src = mcap_messages(recorded.path)
    assert done.messages == len(src) and not done.skipped
    expected = defaultdict(list)
    for topic, t, data in src:
        if topic.startswith("/can/decoded/"):  # std_msgs/String: uint32 length + the JSON
            data = len(data).to_bytes(4, "little") + data
        expected[topic].append((t, data))
    got = defaultdict(list)
    with Reader(bag) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, t, data in reader.messages():
            got[conn.topic].append((t, bytes(data)))
    assert got == expected
    assert types["/battery"] == "woosh_msgs/msg/Battery"
    assert types["/can/decoded/Heartbeat"] == "std_msgs/msg/String"


def test_to_bag_read_with_rosbag(recorded: Recorded, tmp_path: Path) -> None:
    rosbag = pytest.importorskip("rosbag")
    bag = tmp_path / "drive.bag"
    mcap_to_bag(recorded.path, bag)
    with rosbag.Bag(str(bag)) as b:
        info = b.get_type_and_topic_info().topics
        assert info["/odom"].msg_type == "nav_msgs/Odometry"
        assert info["/driver_base/bms"].msg_type == "woosh_msgs/BMS"
        odom = [(t.to_nsec(), m) for _, m, t in b.read_messages(topics=["/odom"])]
        heartbeats = [json.loads(m.data) for _, m, _ in b.read_messages(
            topics=["/can/decoded/Heartbeat"])]
        battery = [m for _, m, _ in b.read_messages(topics=["/battery"])]
    assert len(odom) == len(recorded.states)
    for (t_ns, msg), (t, ekf, _, _) in zip(odom, recorded.states, strict=True):
        assert t_ns == to_ns(t)
        assert (msg.pose.pose.position.x, msg.pose.pose.position.y) == ekf[:2]
    assert heartbeats and all("Uptime" in h for h in heartbeats)
    assert battery[-1].chargeStatus == battery[-1].discharge  # constants from the definition


def test_bag_round_trip(recorded: Recorded, tmp_path: Path) -> None:
    bag, back, bag2 = tmp_path / "a.bag", tmp_path / "b.mcap", tmp_path / "c.bag"
    mcap_to_bag(recorded.path, bag)
    done = bag_to_mcap(bag, back)
    assert done.messages == len(mcap_messages(recorded.path))
    first = Counter((t, time, data if not t.startswith("/can/decoded/") else data[4:])
                    for t, time, data in mcap_messages(back))
    assert first == Counter(mcap_messages(recorded.path))
    with back.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    schemas = {s.name: s for s in summary.schemas.values()}
    assert schemas["woosh_msgs/Battery"].encoding == "ros1msg"
    mcap_to_bag(back, bag2)  # and again: the same bag content
    from rosbags.rosbag1 import Reader

    def content(p: Path) -> list[tuple[str, int, bytes]]:
        with Reader(p) as r:
            return sorted((c.topic, t, bytes(d)) for c, t, d in r.messages())

    assert content(bag) == content(bag2)


def test_cli_and_errors(recorded: Recorded, tmp_path: Path,
                        capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "x.bag"
    assert main(["mcap", "to-bag", str(recorded.path), str(bag)]) == 0
    assert main(["mcap", "from-bag", str(bag), str(tmp_path / "y.mcap")]) == 0
    assert main(["mcap", "info", str(tmp_path / "y.mcap")]) == 0
    out = capsys.readouterr().out
    assert "/battery" in out and "woosh_msgs/Battery" in out
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    for args in (["to-bag", str(junk), str(tmp_path / "j.bag")],
                 ["from-bag", str(recorded.path), str(tmp_path / "j.mcap")],
                 ["to-bag", str(tmp_path / "missing.mcap"), str(tmp_path / "j.bag")],
                 ["info", str(junk)]):
        assert main(["mcap", *args]) == 1
        err = capsys.readouterr().err
        assert err.startswith("lowerbase mcap: error: ") and err.count("\n") == 1
    assert not (tmp_path / "j.bag").exists()
    with pytest.raises(ConfigError):
        mcap_to_bag(recorded.path, tmp_path / "out.txt")
