"""A world run's MCAP (`lowerbase scenario run` of the library's warehouse_localization,
shortened): /scan equals the WorldSim's scans, /map the loaded map cell for cell, /amcl_pose the
localizer's estimates, /ground_truth/pose the truth; decoded with mcap-ros1-support's decoder,
rosbags and (after `lowerbase mcap to-bag`) Debian's rosbag. Recording does not change the
run."""

from __future__ import annotations

import dataclasses
import math
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from lowerbase.cli import main
from lowerbase.cli.scenario import execute
from lowerbase.recording.messages import to_ns
from lowerbase.recording.ros1_types import ros1_types
from lowerbase.recording.world import attach_world, world_topics
from lowerbase.scenarios.catalog import library
from lowerbase.scenarios.wheeled import load_scenario
from lowerbase.world.localization import Localizer
from lowerbase.world.maps import load_map

WORLD_TOPICS = {"/map": "nav_msgs/OccupancyGrid", "/scan": "sensor_msgs/LaserScan",
                "/amcl_pose": "geometry_msgs/PoseWithCovarianceStamped",
                "/ground_truth/pose": "geometry_msgs/PoseStamped", "/tf": "tf2_msgs/TFMessage"}
DURATION = 7.0  #: [s] of warehouse_localization: 6 s of the lane drive, amcl updates on it




@dataclasses.dataclass
class WorldRun:
    path: Path
    result: Any
    #: what the localizer got: scan stamp [ns] -> (ranges, odom pose), and its estimates
    scans: dict[int, np.ndarray]
    estimates: list[Any]


def _scenario() -> Any:
    sc = load_scenario(library()["warehouse_localization"])
    return dataclasses.replace(sc, duration=DURATION, expectations=())


@pytest.fixture(scope="module")
def world_run(tmp_path_factory: pytest.TempPathFactory) -> WorldRun:
    """execute() (what `lowerbase scenario run --mcap` runs), the localizer's inputs and
    outputs taken from the class (the run's WorldSim is built inside)."""
    out = tmp_path_factory.mktemp("world")
    scans: dict[int, np.ndarray] = {}
    estimates: list[Any] = []
    original = Localizer.update

    def update(self: Localizer, odom: Any, scan: Any, truth: Any = None) -> Any:
        scans[to_ns(scan.stamp)] = np.array(scan.ranges, copy=True)
        est = original(self, odom, scan, truth)
        if est is not None:
            estimates.append(est)
        return est

    mp = pytest.MonkeyPatch()
    mp.setattr(Localizer, "update", update)
    try:
        result, _ = execute(_scenario(), out / "report", mcap=out / "world.mcap")
    finally:
        mp.undo()
    return WorldRun(out / "world.mcap", result, scans, estimates)


def read(path: Path) -> dict[str, list[tuple[Any, Any]]]:
    """topic -> [(mcap message, rosbags-decoded message)]."""
    types = ros1_types()
    got: dict[str, list[tuple[Any, Any]]] = defaultdict(list)
    with path.open("rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages():
            if schema is not None and schema.encoding == "ros1msg":
                got[channel.topic].append((msg, types.deserialize(msg.data, schema.name)))
    return got


def test_world_topics_types_and_rates(world_run: WorldRun) -> None:
    got = read(world_run.path)
    with world_run.path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    for topic, type_name in WORLD_TOPICS.items():
        assert types[topic] == type_name
    assert len(got["/map"]) == 1 and got["/map"][0][0].log_time == 0
    n = len(got["/scan"])
    assert abs(n - 25 * DURATION) <= 2  # every tick of the 25 Hz rig
    assert len(got["/ground_truth/pose"]) == n
    stamps = [m.log_time for m, _ in got["/scan"]]
    assert stamps == sorted(stamps) and len(set(stamps)) == n
    assert all(to_ns(d.header.stamp.sec + d.header.stamp.nanosec * 1e-9) // 1000 ==
               m.log_time // 1000 for m, d in got["/scan"])
    assert [d.header.seq for _, d in got["/scan"]] == list(range(1, n + 1))


def test_map_is_the_loaded_map_cell_for_cell(world_run: WorldRun) -> None:
    (_, msg), = read(world_run.path)["/map"]
    grid = load_map("warehouse")
    info = msg.info
    assert (info.width, info.height) == (grid.width, grid.height)
    assert info.resolution == np.float32(grid.resolution)
    assert (info.origin.position.x, info.origin.position.y) == grid.origin[:2]
    assert msg.header.frame_id == "map"
    cells = np.asarray(msg.data, dtype=np.int8).reshape(info.height, info.width)
    assert np.array_equal(cells, grid.data)
    assert (cells == 100).sum() > 1000 and (cells == 0).sum() > 100_000  # a real map


def test_scans_the_localizer_used_are_in_the_file_bit_for_bit(world_run: WorldRun) -> None:
    scans = {m.log_time: d for m, d in read(world_run.path)["/scan"]}
    assert len(world_run.scans) >= 10  # amcl updates every 0.2 m of the 0.5 m/s drive
    for stamp, ranges in world_run.scans.items():
        msg = scans[stamp]
        assert msg.ranges.tobytes() == ranges.astype(np.float32).tobytes(), stamp
        assert msg.header.frame_id == "base_link"


def test_every_scan_fits_the_map_at_the_true_pose(world_run: WorldRun) -> None:
    """The other ticks (cast by the recorder's own rig) against a noise-free cast of the
    same lidars at the recorded true pose: within the 12 mm range noise."""
    from lowerbase.world.lidar import LidarRig
    from lowerbase.world.raycast import Scene
    from lowerbase.world.sensors import sensors_from_profile_file

    got = read(world_run.path)
    truth = {m.log_time: d.pose for m, d in got["/ground_truth/pose"]}
    sensors = sensors_from_profile_file()
    exact = LidarRig([dataclasses.replace(lc, range_sigma=0.0) for lc in sensors.lidars],
                     sensors.scan)
    scene = Scene(load_map("warehouse"))
    checked = 0
    for m, scan in got["/scan"][::5]:
        p = truth[m.log_time]
        yaw = 2.0 * math.atan2(p.orientation.z, p.orientation.w)
        ref = exact.scan(scene, (p.position.x, p.position.y, yaw), m.log_time / 1e9).ranges
        both = np.isfinite(ref) & np.isfinite(scan.ranges)
        assert both.sum() > 300
        assert np.array_equal(np.isfinite(ref), np.isfinite(scan.ranges)) or \
            (np.isfinite(ref) != np.isfinite(scan.ranges)).sum() < 5
        err = np.abs(scan.ranges[both] - ref[both])
        assert np.percentile(err, 95) < 0.03, m.log_time
        checked += 1
    assert checked >= 30


def test_amcl_pose_and_map_to_odom(world_run: WorldRun) -> None:
    got = read(world_run.path)
    amcl = [d for _, d in got["/amcl_pose"]]
    assert len(amcl) == len(world_run.estimates) >= 10
    for msg, est in zip(amcl, world_run.estimates, strict=True):
        p = msg.pose.pose
        assert (p.position.x, p.position.y) == est.pose[:2]
        assert math.isclose(2.0 * math.atan2(p.orientation.z, p.orientation.w), est.pose[2],
                            abs_tol=1e-12)
        assert tuple(msg.pose.covariance) == est.covariance
        assert msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 == \
            pytest.approx(est.stamp, abs=1e-9)
    m2o = [t for _, d in got["/tf"] for t in d.transforms if t.header.frame_id == "map"]
    assert m2o and all(t.child_frame_id == "odom" for t in m2o)
    last, est = m2o[-1].transform, world_run.estimates[-1]
    assert (last.translation.x, last.translation.y) == pytest.approx(est.map_to_odom[:2])


def test_recording_does_not_change_the_run(world_run: WorldRun, tmp_path: Path) -> None:
    plain, _ = execute(_scenario(), tmp_path / "plain", mcap=False)
    for column in ("amcl_x", "amcl_y", "amcl_yaw", "ekf_x", "truth_x", "truth_yaw"):
        assert np.array_equal(plain.trace[column], world_run.result.trace[column],
                              equal_nan=True), column
    assert np.isfinite(plain.trace["amcl_error"]).sum() > 30


def test_decodes_with_mcap_ros1_support(world_run: WorldRun) -> None:
    decoder = pytest.importorskip("mcap_ros1.decoder")
    seen: dict[str, Any] = {}
    with world_run.path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[decoder.DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=list(WORLD_TOPICS)):
            seen.setdefault(channel.topic, msg)
    assert set(seen) == set(WORLD_TOPICS)
    grid = load_map("warehouse")
    assert list(seen["/map"].data[:grid.width]) == grid.data[0].tolist()
    assert len(seen["/scan"].ranges) == 720 and seen["/scan"].header.frame_id == "base_link"


def test_to_bag_read_with_rosbag(world_run: WorldRun, tmp_path: Path) -> None:
    bag = tmp_path / "world.bag"
    assert main(["mcap", "to-bag", str(world_run.path), str(bag)]) == 0
    from rosbags.rosbag1 import Reader

    with Reader(bag) as r:
        kinds = {c.topic: c.msgtype for c in r.connections}
    assert kinds["/scan"] == "sensor_msgs/msg/LaserScan"
    rosbag = pytest.importorskip("rosbag")
    mcap = read(world_run.path)
    with rosbag.Bag(str(bag)) as b:
        info = b.get_type_and_topic_info().topics
        assert {t: info[t].msg_type for t in WORLD_TOPICS} == WORLD_TOPICS
        scans = [(t.to_nsec(), msg) for _, msg, t in b.read_messages(topics=["/scan"])]
        (_, grid_msg, _), = b.read_messages(topics=["/map"])
    assert [t for t, _ in scans] == [m.log_time for m, _ in mcap["/scan"]]
    for (_, msg), (_, ref) in zip(scans, mcap["/scan"], strict=True):
        assert np.array_equal(np.asarray(msg.ranges, dtype=np.float32), ref.ranges,
                              equal_nan=True)
    assert np.array_equal(np.asarray(grid_msg.data, dtype=np.int8).reshape(
        grid_msg.info.height, grid_msg.info.width), load_map("warehouse").data)


def test_camera_depth_and_the_plan_hook(tmp_path: Path) -> None:
    """A world with its camera: each rendered frame's depth image, bit for bit; and the
    navigation hook `world_topics.plan` writes nav_msgs/Path in map."""
    from lowerbase.recording.mcap_writer import McapRecorder
    from lowerbase.world.sim import WorldConfig, WorldSim

    world = WorldSim(WorldConfig(map="empty_room", localization="truth", camera=True))
    frames: list[Any] = []
    path = tmp_path / "cam.mcap"
    with McapRecorder(path) as rec:
        attach_world(rec, world)
        for _ in range(3):
            world.run(0.07)
            frames.append(world.frame)
        world_topics(rec).plan(1.5, [(1.0, 2.0, 0.0), (3.0, 2.5, 1.0)])
    got = read(path)
    depth = [d for _, d in got["/camera_1/depth/image_raw"]]
    assert len(depth) >= 3 and all(f is not None for f in frames)
    by_stamp = {to_ns(d.header.stamp.sec + d.header.stamp.nanosec * 1e-9): d for d in depth}
    for f in frames:
        d = by_stamp[to_ns(f.stamp)]
        assert (d.encoding, d.height, d.width) == ("16UC1", *f.depth.shape)
        assert bytes(d.data) == f.depth.astype("<u2").tobytes()
    (m, plan), = got["/move_base/NavfnROS/plan"]
    assert m.log_time == 1_500_000_000 and plan.header.frame_id == "map"
    assert [(p.pose.position.x, p.pose.position.y) for p in plan.poses] == [(1.0, 2.0),
                                                                           (3.0, 2.5)]


def test_live_view_gets_the_map_when_it_subscribes_later() -> None:
    """/map is latched in the live view: a client subscribing after the start gets it (once),
    cell for cell; a file sink is not sent it again."""
    from lowerbase.recording.live import FoxgloveSink
    from lowerbase.recording.publisher import RunPublisher
    from lowerbase.world.sim import WorldConfig, WorldSim
    from tests.recording.foxglove_client import FoxgloveClient

    sink = FoxgloveSink("127.0.0.1", 0)
    pub = RunPublisher([sink])
    world = WorldSim(WorldConfig(map="empty_room", localization="truth"))
    client = None
    try:
        attach_world(pub, world)
        world.run(0.2)
        assert pub.counts["/map"] == 0  # nobody wanted it yet
        client = FoxgloveClient(sink.url)
        client.pump_until(lambda: "/map" in client.channels)  # type: ignore[union-attr]
        client.subscribe("/map")
        deadline = time.monotonic() + 20.0  # the server registers it in its own thread
        while not sink.subscribed("/map"):
            assert time.monotonic() < deadline, "the subscription never arrived"
            time.sleep(0.01)
        world.run(0.2)
        client.pump_until(lambda: bool(client.messages.get("/map")))  # type: ignore[union-attr]
        world.run(0.5)
    finally:
        pub.close()
    assert pub.counts["/map"] == 1
    (_, data), = client.messages["/map"]
    client.close()
    msg = ros1_types().deserialize(data, "nav_msgs/OccupancyGrid")
    grid = load_map("empty_room")
    assert np.array_equal(np.asarray(msg.data, dtype=np.int8).reshape(grid.data.shape),
                          grid.data)
