"""fastser's world packers (LaserScan, OccupancyGrid, PoseWithCovarianceStamped, PoseStamped,
Path, Image) give exactly rosbags' ROS1 bytes for the messages lowerbase.recording.messages
builds from the same arguments, genpy's where importable, and decode to the inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lowerbase.recording import fastser as fs
from lowerbase.recording import messages as m
from lowerbase.recording.ros1_types import Ros1Types, ros1_types
from tests.recording.test_fast_serialise import (
    _float,
    _genpy,
    _genpy_bytes,
    _header,
    _ns,
    _rng,
    _seq,
    _string,
)

N = 100


@pytest.fixture(scope="module")
def types() -> Ros1Types:
    return ros1_types()


def _f32(rng_value: float) -> float:
    """A float32 value (LaserScan's angles are float32: packing a float64 rounds it)."""
    return float(np.float32(rng_value)) if math.isfinite(rng_value) and \
        abs(rng_value) < 3e38 else rng_value


def test_laser_scan(types: Ros1Types) -> None:
    rng, cls = _rng("scan"), _genpy(types, "sensor_msgs/LaserScan")
    nprng = np.random.default_rng(1)
    for _ in range(N):
        seq, ns, frame = _seq(rng), _ns(rng), _string(rng)
        angles = [_f32(rng.uniform(-4, 4)) for _ in range(7)]
        n = rng.choice([0, 1, 720, rng.randint(0, 2000)])
        ranges = nprng.uniform(0, 40, n).astype(np.float32)
        if n:  # REP-117 values
            ranges[nprng.integers(0, n, 3)] = [np.inf, -np.inf, np.nan]
        fast = fs.laser_scan(seq, ns, frame, angles, ranges)
        assert fast == types.serialize(m.laser_scan_msg(
            types, _header(types, seq, ns, frame), angles, ranges))
        if cls is not None:
            assert _genpy_bytes(cls, fast) == fast
        back = types.deserialize(fast, "sensor_msgs/LaserScan")
        assert back.ranges.tobytes() == ranges.tobytes() and back.intensities.size == 0
        assert [back.angle_min, back.range_max] == [angles[0], angles[6]]


def test_occupancy_grid(types: Ros1Types) -> None:
    rng, cls = _rng("grid"), _genpy(types, "nav_msgs/OccupancyGrid")
    nprng = np.random.default_rng(2)
    for _ in range(30):
        seq, ns, load, frame = _seq(rng), _ns(rng), _ns(rng), _string(rng)
        h, w = rng.randint(1, 60), rng.randint(1, 80)
        cells = nprng.choice(np.array([-1, 0, 100, 42], dtype=np.int8), (h, w))
        origin = (_float(rng), _float(rng), rng.uniform(-3, 3))
        res = _f32(rng.uniform(0.01, 1.0))
        fast = fs.occupancy_grid(seq, ns, frame, load, res, origin, cells)
        load_time = types.message("builtin_interfaces/Time", sec=load // 10**9,
                                  nanosec=load % 10**9)
        assert fast == types.serialize(m.occupancy_grid_msg(
            types, _header(types, seq, ns, frame), load_time, res, origin, cells))
        if cls is not None:
            assert _genpy_bytes(cls, fast) == fast
        back = types.deserialize(fast, "nav_msgs/OccupancyGrid")
        assert (back.info.width, back.info.height) == (w, h)
        assert np.array_equal(back.data.reshape(h, w), cells)  # row 0 first


def test_poses_and_path(types: Ros1Types) -> None:
    rng = _rng("poses")
    classes = {n: _genpy(types, n) for n in ("geometry_msgs/PoseWithCovarianceStamped",
                                               "geometry_msgs/PoseStamped", "nav_msgs/Path")}
    for _ in range(N):
        seq, ns, frame = _seq(rng), _ns(rng), _string(rng)
        pose = (_float(rng), _float(rng), rng.uniform(-10, 10))
        cov = [_float(rng) for _ in range(36)]
        poses = [(_float(rng), _float(rng), rng.uniform(-4, 4))
                 for _ in range(rng.choice([0, 1, 5, 40]))]
        head = _header(types, seq, ns, frame)
        got = {"geometry_msgs/PoseWithCovarianceStamped":
               (fs.pose_with_covariance(seq, ns, frame, pose, cov),
                m.pose_with_covariance_msg(types, head, pose, cov)),
               "geometry_msgs/PoseStamped": (fs.pose_stamped(seq, ns, frame, pose),
                                             m.pose_stamped_msg(types, head, pose)),
               "nav_msgs/Path": (fs.path(seq, ns, frame, poses),
                                 m.path_msg(types, head, poses))}
        for name, (fast, ref) in got.items():
            assert fast == types.serialize(ref), name
            if classes[name] is not None:
                assert _genpy_bytes(classes[name], fast) == fast
    back = types.deserialize(fs.path(3, 5, "map", [(1.0, 2.0, 0.5)]), "nav_msgs/Path")
    p = back.poses[0]
    assert (p.header.frame_id, p.pose.position.x, p.pose.position.y) == ("map", 1.0, 2.0)
    assert math.isclose(2 * math.atan2(p.pose.orientation.z, p.pose.orientation.w), 0.5)


@pytest.mark.parametrize("encoding, shape, dtype", [("16UC1", (48, 64), np.uint16),
                                                    ("rgb8", (3, 5, 3), np.uint8),
                                                    ("16UC1", (0, 4), np.uint16)])
def test_image(types: Ros1Types, encoding: str, shape: tuple[int, ...], dtype: type) -> None:
    cls = _genpy(types, "sensor_msgs/Image")
    array: np.ndarray = np.random.default_rng(3).integers(
        0, np.iinfo(dtype).max, shape).astype(dtype)
    fast = fs.image(9, 123_000_000_456, "camera_1_depth_optical_frame", encoding, array)
    head = _header(types, 9, 123_000_000_456, "camera_1_depth_optical_frame")
    assert fast == types.serialize(m.image_msg(types, head, encoding, array))
    if cls is not None:
        assert _genpy_bytes(cls, fast) == fast
    back = types.deserialize(fast, "sensor_msgs/Image")
    assert (back.height, back.width, back.encoding) == (*shape[:2], encoding)
    assert bytes(back.data) == array.astype(array.dtype.newbyteorder("<")).tobytes()
