"""The world node stamps each sensor output with the /clock time of the truth sample it was
rendered from (``--publish-clock``), not with rospy's newest /clock: the camera's frames and
clouds as the lidar's scans. navigation marks each cloud at the robot's pose of its stamp, so
a stamp off the rendering pose puts the cloud's obstacles off by the motion in between.
WorldNode without a master; rospy's newest /clock is a stand-in 0.75 s past the sample (the
largest lag of the world's /clock behind its truth measured at K=2, docs/robot.md)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from lowerbase.world.maps import load_map
from lowerbase.world.sensors import sensors_from_profile_file
from lowerbase.world.sim_clock import TruthTime
from lowerbase.world.truth_stream import TruthSample
from tests.driver.conftest import require_ros


class Truth:
    """A --publish-clock truth source holding one sample at emulator time ``t``."""

    def __init__(self, t: float) -> None:
        self.time = TruthTime()
        self._sample = TruthSample(t, 1.0, 0.5, 0.2, 0.3, 0.1)
        self.time.clock(self._sample)

    def sample(self) -> TruthSample:
        return self._sample

    def age(self) -> float:
        return 0.0


def test_camera_frames_carry_the_truth_samples_clock_time() -> None:
    require_ros(("rospy", "sensor_msgs.msg"))
    from lowerbase.world.node import WorldNode, WorldSetup

    grid = load_map("empty_room")
    node = WorldNode(WorldSetup(grid, sensors_from_profile_file(), (5.0, 4.0, 0.0)),
                     Truth(12.34))
    assert node.camera is not None
    import rospy

    node.rospy = SimpleNamespace(Time=SimpleNamespace(
        now=lambda: rospy.Time.from_sec(12.34 + 0.75), from_sec=rospy.Time.from_sec))
    sent: dict[str, Any] = {}
    node._pubs = {k: SimpleNamespace(publish=lambda m, k=k: sent.setdefault(k, m))
                  for k in ("color", "color_info", "depth", "depth_info", "points",
                            "no_planes")}
    node.frame_once()
    assert set(sent) == set(node._pubs)
    for name, msg in sent.items():
        assert abs(msg.header.stamp.to_sec() - 12.34) < 1e-6, (name, msg.header.stamp)
