"""The world as a ROS node, black-box: a real rosmaster, `lowerbase emulate --truth-udp` and
`lowerbase world --map empty_room` in processes of their own, /odom from `rostopic pub` (the
driver's part), checked by the driver tests' probe node and by rosservice."""

from __future__ import annotations

import math
import os
import subprocess
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from lowerbase.world.maps import load_map
from tests.conftest import Proc, bus_cli_args, free_udp_port
from tests.driver.conftest import ros_master, woosh_msgs_build  # noqa: F401 (fixtures)
from tests.driver.test_node_ros import PROBE, Probe

START = (5.0, 4.0, 0.0)  # empty_room's place "start": the emulator's origin on the map
TOPICS = {
    "/map": "nav_msgs/OccupancyGrid",
    "/scan": "sensor_msgs/LaserScan",
    "/amcl_pose": "geometry_msgs/PoseWithCovarianceStamped",
    "/movebase_pose2d": "geometry_msgs/Pose2D",
    "/tf": "tf2_msgs/TFMessage",
    "/tf_static": "tf2_msgs/TFMessage",
}


@pytest.fixture(scope="module")
def world(ros_master: Any, tmp_path_factory: pytest.TempPathFactory  # noqa: F811
          ) -> Iterator[dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("world_node")
    bus = {"interface": "udp_multicast", "channel": "239.74.163.99", "port": free_udp_port(),
           "hop_limit": 0}
    truth_port = free_udp_port()
    env = ros_master.env
    procs: list[Proc] = []
    odom: subprocess.Popen[bytes] | None = None
    probe: Probe | None = None
    try:
        world_proc = Proc(["world", "--map", "empty_room", "--truth-udp", str(truth_port)],
                          {k: v for k, v in env.items() if k != "ROS_IP"})
        procs.append(world_proc)
        world_proc.wait_for("on ROS master", timeout=30.0)
        emulator = Proc(["emulate", *bus_cli_args(bus), "--truth-udp",
                         f"127.0.0.1:{truth_port}"], env)
        procs.append(emulator)
        world_proc.wait_for("ground truth received", timeout=30.0)
        odom = subprocess.Popen(
            ["rostopic", "pub", "-r", "20", "/odom", "nav_msgs/Odometry",
             "{header: {frame_id: odom}, child_frame_id: base_link, "
             "pose: {pose: {orientation: {w: 1.0}}}}"],
            env={**os.environ, **env}, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        script = tmp / "probe.py"
        script.write_text(PROBE)
        probe = Probe(script, env, TOPICS)
        yield {"probe": probe, "env": env, "world": world_proc}
    finally:
        if probe is not None:
            probe.close()
        if odom is not None:
            odom.terminate()
            odom.wait(10)
        for p in reversed(procs):
            p.stop()


def _call_cli(env: dict[str, str], *args: str) -> str:
    out = subprocess.run(list(args), env={**os.environ, **env}, capture_output=True,
                         text=True, timeout=30)
    return out.stdout + out.stderr


@pytest.mark.ros
@pytest.mark.process
def test_map_is_latched_and_get_map_serves_the_map_file(world: dict[str, Any]) -> None:
    probe: Probe = world["probe"]
    grid = load_map("empty_room")
    stats = probe.wait_for(lambda s: s["/map"]["count"] >= 1, 20.0, "/map")
    for msg in (stats["/map"]["msg"], probe.ask(op="call", name="/aic_map_server/get_map",
                                                type="nav_msgs/GetMap")["map"]):
        info = msg["info"]
        assert (info["width"], info["height"]) == (grid.width, grid.height)
        assert info["resolution"] == pytest.approx(grid.resolution)
        assert msg["header"]["frame_id"] == "map"
        assert np.array_equal(np.asarray(msg["data"], np.int8), grid.data.ravel())


@pytest.mark.ros
@pytest.mark.process
def test_scan_rate_beams_and_ranges_match_the_room(world: dict[str, Any]) -> None:
    probe: Probe = world["probe"]
    probe.wait_for(lambda s: s["/scan"]["count"] >= 5, 20.0, "/scan")
    since = probe.ask(op="now")["t"]
    time.sleep(2.0)  # a measurement window, not a wait for a condition
    stats = probe.ask(op="stats", since=since)
    # by the scans' stamps: a backlog the busy probe reads at once is not a faster /scan
    assert 0.5 * 25 <= stats["/scan"]["rate"] <= 1.2 * 25, stats["/scan"]["recent"]
    scan = stats["/scan"]["msg"]
    assert scan["header"]["frame_id"] == "base_link"
    ranges = np.asarray(scan["ranges"], float)
    assert ranges.size == 720
    angles = scan["angle_min"] + np.arange(720) * scan["angle_increment"]
    # the room's inner faces, read off the map file; the robot at START, heading 0
    grid = load_map("empty_room")
    occ = grid.occupied()
    row = int(START[1] / grid.resolution)
    col = int(START[0] / grid.resolution)
    cols, rows = np.where(occ[row])[0], np.where(occ[:, col])[0]
    east = cols[cols > col].min() * grid.resolution
    south = (rows[rows < row].max() + 1) * grid.resolution
    checked = 0
    # (the west wall has the charger on it, the north wall a niche: not a plain face)
    for face, direction in ((east - START[0], 0.0), (START[1] - south, -math.pi / 2)):
        near = np.abs(np.angle(np.exp(1j * (angles - direction)))) < math.radians(30)
        expected = face / np.cos(angles[near] - direction)
        assert np.allclose(ranges[near], expected, atol=0.08), (direction, ranges[near])
        checked += int(near.sum())
    assert checked > 200


@pytest.mark.ros
@pytest.mark.process
def test_localization_tf_and_its_controls(world: dict[str, Any]) -> None:
    probe: Probe = world["probe"]
    stats = probe.wait_for(lambda s: s["/amcl_pose"]["count"] >= 1
                           and s["/movebase_pose2d"]["count"] >= 1, 20.0, "/amcl_pose")
    pose = stats["/amcl_pose"]["msg"]["pose"]["pose"]["position"]
    assert math.hypot(pose["x"] - START[0], pose["y"] - START[1]) < 0.1
    assert stats["/amcl_pose"]["msg"]["header"]["frame_id"] == "map"
    p2d = stats["/movebase_pose2d"]["msg"]
    assert math.hypot(p2d["x"] - START[0], p2d["y"] - START[1]) < 0.1
    probe.wait_for(lambda s: any(t["header"]["frame_id"] == "map" and t["child_frame_id"] ==
                                 "odom" for t in s["/tf"]["msg"]["transforms"]),
                   10.0, "TF map->odom")
    static = {t["child_frame_id"] for t in stats["/tf_static"]["msg"]["transforms"]}
    assert {"laser_front", "laser_back", "camera_1_link", "camera_1_depth_optical_frame",
            "camera_1_color_optical_frame"} <= static
    # stopped: an /initialpose does not bring an /amcl_pose
    reply = probe.ask(op="call", name="/start_localization", type="std_srvs/SetBool",
                      args={"data": False})
    assert reply == {"success": True, "message": "localization stopped"}
    count = probe.ask(op="stats")["/amcl_pose"]["count"]
    initial = ("{header: {frame_id: map}, pose: {pose: {position: {x: 5.2, y: 4.1}, "
               "orientation: {w: 1.0}}, covariance: [0.05, 0, 0, 0, 0, 0, 0, 0.05, 0, 0, 0, 0, "
               "0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.02]}}")
    _call_cli(world["env"], "rostopic", "pub", "-1", "/initialpose",
              "geometry_msgs/PoseWithCovarianceStamped", initial)
    probe.wait_for(lambda s: s["/scan"]["count"] > 0, 1.0, "scans")
    time.sleep(1.0)  # a window in which no /amcl_pose may come
    assert probe.ask(op="stats")["/amcl_pose"]["count"] == count
    # started again: the /initialpose taken while stopped is used at once
    reply = probe.ask(op="call", name="/start_localization", type="std_srvs/SetBool",
                      args={"data": True})
    assert reply["success"] is True
    stats = probe.wait_for(lambda s: s["/amcl_pose"]["count"] > count, 10.0, "/amcl_pose")
    count = stats["/amcl_pose"]["count"]
    # /initialpose re-initialises: a new estimate at once (the robot stands still)
    _call_cli(world["env"], "rostopic", "pub", "-1", "/initialpose",
              "geometry_msgs/PoseWithCovarianceStamped", initial)
    stats = probe.wait_for(lambda s: s["/amcl_pose"]["count"] > count, 10.0,
                           "/amcl_pose after /initialpose")
    pose = stats["/amcl_pose"]["msg"]["pose"]["pose"]["position"]
    assert math.hypot(pose["x"] - START[0], pose["y"] - START[1]) < 0.25


@pytest.mark.ros
@pytest.mark.process
def test_set_map_with_a_nan_pose_fails_and_changes_nothing(world: dict[str, Any]) -> None:
    probe: Probe = world["probe"]
    request = ("{map: {info: {resolution: 0.05, width: 2, height: 2, origin: {orientation: "
               "{w: 1.0}}}, data: [0, 0, 0, 0]}, initial_pose: {pose: {pose: {position: "
               "{x: .nan, y: 1.0}, orientation: {w: 1.0}}}}}")
    out = _call_cli(world["env"], "rosservice", "call", "/set_map", request)
    assert "success: False" in out, out
    grid = load_map("empty_room")
    served = probe.ask(op="call", name="/aic_map_server/get_map", type="nav_msgs/GetMap")["map"]
    assert (served["info"]["width"], served["info"]["height"]) == (grid.width, grid.height)
    assert np.array_equal(np.asarray(served["data"], np.int8), grid.data.ravel())
    assert world["world"].popen.poll() is None  # the node is still running


@pytest.mark.ros
@pytest.mark.process
def test_camera_topics(world: dict[str, Any]) -> None:
    import yaml

    def first(topic: str) -> dict[str, Any]:  # without the (large) arrays
        out = _call_cli(world["env"], "rostopic", "echo", "-n", "1", "--noarr", topic)
        doc: dict[str, Any] = yaml.safe_load(out.split("\n---")[0])
        return doc

    depth = first("/camera_1/depth/image_raw")
    assert (depth["width"], depth["height"], depth["encoding"]) == (640, 480, "16UC1")
    assert depth["header"]["frame_id"] == "camera_1_depth_optical_frame"
    color = first("/camera_1/color/image_raw")
    assert color["encoding"] == "rgb8" and color["step"] == 640 * 3
    assert color["header"]["frame_id"] == "camera_1_color_optical_frame"
    cloud = first("/camera_1/depth/points")
    assert cloud["point_step"] == 12 and cloud["width"] > 0
    assert cloud["header"]["frame_id"] == "camera_1_depth_optical_frame"
    assert 0 < first("/camera_1/depth/cloud_without_planes")["width"] < cloud["width"]


#: subscribes to a depth frame, its cloud and both camera_infos of one stamp; prints them as JSON
CAMERA_SCRIPT = r'''
import json, sys
import numpy as np
import rospy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
rospy.init_node("camera_probe", anonymous=True)
got = {}
def keep(name):
    def cb(msg):
        got.setdefault(msg.header.stamp.to_nsec(), {})[name] = msg
    return cb
for name, topic, cls in (("depth", "depth/image_raw", Image),
                         ("points", "depth/points", PointCloud2),
                         ("depth_info", "depth/camera_info", CameraInfo),
                         ("color_info", "color/camera_info", CameraInfo)):
    rospy.Subscriber("/camera_1/" + topic, cls, keep(name), queue_size=5)
deadline = rospy.Time.now() + rospy.Duration(30.0)
while not rospy.is_shutdown() and rospy.Time.now() < deadline:
    full = [s for s, m in list(got.items()) if len(m) == 4]
    if full:
        m = got[full[0]]
        d, p = m["depth"], m["points"]
        depth = np.frombuffer(d.data, np.uint16).reshape(d.height, d.width)
        xyz = np.frombuffer(p.data, np.float32).reshape(-1, 3)
        print(json.dumps({
            "depth": depth.tolist(), "points": xyz.tolist(),
            **{k: {"K": list(m[k].K), "P": list(m[k].P), "D": list(m[k].D), "R": list(m[k].R),
                   "width": m[k].width, "height": m[k].height, "model": m[k].distortion_model,
                   "frame_id": m[k].header.frame_id} for k in ("depth_info", "color_info")}}))
        sys.exit(0)
    rospy.sleep(0.05)
sys.exit("no complete camera frame in 30 s")
'''


@pytest.mark.ros
@pytest.mark.process
def test_camera_info_is_the_pinhole_the_frames_are_rendered_with(
        world: dict[str, Any], tmp_path: Any) -> None:
    """K against the rendering: every point of /depth/points projects through the published K
    onto the centre of a pixel, whose /depth/image_raw value is the point's depth."""
    import json
    import sys

    from lowerbase.world.sensors import sensors_from_profile_file

    script = tmp_path / "camera_probe.py"
    script.write_text(CAMERA_SCRIPT)
    out = subprocess.run([sys.executable, str(script)], env={**os.environ, **world["env"]},
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout)
    cam = sensors_from_profile_file().camera
    assert cam is not None
    for name, frame in (("depth_info", "camera_1_depth_optical_frame"),
                        ("color_info", "camera_1_color_optical_frame")):
        info = got[name]
        assert info["frame_id"] == frame and info["model"] == "plumb_bob"
        assert (info["width"], info["height"]) == (cam.width, cam.height) == (640, 480)
        assert info["K"] == pytest.approx([cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1])
        assert info["P"] == pytest.approx([cam.fx, 0, cam.cx, 0, 0, cam.fy, cam.cy, 0, 0, 0, 1, 0])
        assert info["D"] == [0.0] * 5 and info["R"] == [1, 0, 0, 0, 1, 0, 0, 0, 1]
    k = np.asarray(got["depth_info"]["K"]).reshape(3, 3)
    depth = np.asarray(got["depth"], float) / 1000.0  # [m]
    xyz = np.asarray(got["points"], float)
    assert len(xyz) > 1000
    uvw = xyz @ k.T
    u, v = uvw[:, 0] / uvw[:, 2], uvw[:, 1] / uvw[:, 2]
    # on pixel centres (float32 points: a few 1e-4 px of rounding)
    assert np.abs(u - np.round(u)).max() < 0.01 and np.abs(v - np.round(v)).max() < 0.01
    col, row = np.round(u).astype(int), np.round(v).astype(int)
    assert col.min() >= 0 and col.max() < 640 and row.min() >= 0 and row.max() < 480
    # the depth image holds the same depth, to its 1 mm quantisation
    assert np.abs(depth[row, col] - xyz[:, 2]).max() < 0.0015
    # and every pixel with a depth has its point
    assert np.count_nonzero(depth) == len(xyz)
