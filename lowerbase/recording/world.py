"""A world run's channels: /map, /scan, /amcl_pose, map -> odom on /tf, the truth on the map.

:class:`WorldTopics` writes the world node's topics (``lowerbase world``, docs/world.md) through
a :class:`~lowerbase.recording.publisher.RunPublisher`'s sinks, packed by :mod:`.fastser`:

* ``/map`` nav_msgs/OccupancyGrid (frame ``map``): once, when a run starts; latched: a sink
  that starts wanting it later (a live view subscribed since) gets it at the next scan tick;
* ``/scan`` sensor_msgs/LaserScan (``base_link``): every scan tick of the lidar rig (25 Hz);
* ``/amcl_pose`` geometry_msgs/PoseWithCovarianceStamped (``map``): each filter update;
* ``/tf`` tf2_msgs/TFMessage map -> odom: with each scan once the localizer has an estimate;
* ``/ground_truth/pose`` geometry_msgs/PoseStamped (``map``): the true pose of each scan tick
  (where the scan was cast from);
* ``/camera_1/depth/image_raw`` sensor_msgs/Image 16UC1 [mm]: each frame, when the world
  renders its camera;
* :meth:`WorldTopics.plan`: nav_msgs/Path on ``/move_base/NavfnROS/plan`` (or any topic), for
  a navigation stack to call.

:class:`WorldFeed` follows a ``lowerbase.world.sim.WorldSim`` step by step. Its scans are
cast lazily (only when the localizer uses one), and the lidars' noise generators are stateful,
so the feed never makes the world cast: a scan the world cast (the localizer's) is written as
it is, any other tick is cast by the feed's own copy of the rig (the same lidars, noise seeds
offset by :data:`NOISE_SEED_OFFSET`), from the tick's true pose at the tick's time. A run is
therefore the same with and without a recording (tested). A tick's scan is written when the
next tick comes (the localizer takes it at most one /odom period after the tick) or at close,
with the tick's stamp as header stamp and log time.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

from lowerbase.recording import fastser as fs
from lowerbase.recording.messages import to_ns
from lowerbase.recording.publisher import RunPublisher

MAP_TOPIC = "/map"
SCAN_TOPIC = "/scan"
AMCL_TOPIC = "/amcl_pose"
TRUTH_POSE_TOPIC = "/ground_truth/pose"
PLAN_TOPIC = "/move_base/NavfnROS/plan"
TF_TOPIC = "/tf"
NOISE_SEED_OFFSET = 1000  #: the feed's own rig: each lidar's noise seed plus this

Pose = Sequence[float]


class WorldTopics:
    """The world's messages on ``publisher``'s sinks; ``t`` [s] is the run's time."""

    def __init__(self, publisher: RunPublisher, *, map_frame: str = "map",
                 odom_frame: str | None = None) -> None:
        self.pub = publisher
        self.map_frame = map_frame
        self.odom_frame = odom_frame or publisher.settings.odom_frame
        self._map: tuple[int, Any] | None = None
        self._map_seq = 0
        self._map_to: set[int] = set()  #: sinks (ids) that wanted /map when it was last sent

    def map(self, t: float, grid: Any) -> None:
        """/map: ``grid`` a ``lowerbase.world.grid.OccupancyGrid``, stamped and loaded at t.
        Latched: :meth:`latch_map` sends it again to a sink that starts wanting it."""
        ns = to_ns(t)
        self._map = (ns, grid)
        pairs = self.pub._ros1(MAP_TOPIC, "nav_msgs/OccupancyGrid")
        self._map_seq = self.pub._seq[MAP_TOPIC]
        self._map_to = {id(s) for s, _ in pairs}
        if pairs:
            self.pub._emit(MAP_TOPIC, pairs, self._map_bytes(), ns)

    def _map_bytes(self) -> bytes:
        assert self._map is not None
        ns, grid = self._map
        return fs.occupancy_grid(self._map_seq, ns, self.map_frame, ns, grid.resolution,
                                 grid.origin, grid.data)

    def latch_map(self) -> None:
        """The last /map again to each sink that did not want it when it was last sent (a
        live view subscribed since): what a latched ROS topic does for a new subscriber."""
        if self._map is None:
            return
        pairs = self.pub._open(MAP_TOPIC, lambda: self.pub.ros1_spec(
            MAP_TOPIC, "nav_msgs/OccupancyGrid"))
        new = [(s, h) for s, h in pairs if id(s) not in self._map_to]
        self._map_to = {id(s) for s, _ in pairs}
        if new:
            self.pub._emit(MAP_TOPIC, new, self._map_bytes(), self._map[0])

    def wants_scan(self) -> bool:
        """Whether any sink takes /scan now (if not, it need not be cast)."""
        return self.pub.wants(SCAN_TOPIC, "sensor_msgs/LaserScan")

    def scan(self, scan: Any) -> None:
        """/scan from a ROS-free ``lowerbase.world.lidar.LaserScan`` (its stamp and frame)."""
        ns = to_ns(scan.stamp)
        angles = (scan.angle_min, scan.angle_max, scan.angle_increment, scan.time_increment,
                  scan.scan_time, scan.range_min, scan.range_max)
        self.pub.send(SCAN_TOPIC, "sensor_msgs/LaserScan", lambda seq: fs.laser_scan(
            seq, ns, scan.frame_id, angles, scan.ranges), ns)

    def amcl_pose(self, t: float, estimate: Any) -> None:
        """/amcl_pose of a ``PoseEstimate`` (pose and 6x6 covariance), header at its stamp,
        written at ``t``."""
        stamp = to_ns(estimate.stamp)
        self.pub.send(AMCL_TOPIC, "geometry_msgs/PoseWithCovarianceStamped",
                      lambda seq: fs.pose_with_covariance(
                          seq, stamp, self.map_frame, estimate.pose, estimate.covariance),
                      to_ns(t))

    def map_to_odom(self, t: float, pose: Pose) -> None:
        """/tf: map -> odom (tf2_ros' broadcaster: inner header seq 0)."""
        ns = to_ns(t)
        x, y, yaw = pose
        self.pub.send(TF_TOPIC, "tf2_msgs/TFMessage", lambda _: fs.tf_planar(
            ns, self.map_frame, self.odom_frame, (x, y, yaw)), ns)

    def truth_pose(self, t: float, pose: Pose) -> None:
        """/ground_truth/pose: the true pose on the map."""
        ns = to_ns(t)
        self.pub.send(TRUTH_POSE_TOPIC, "geometry_msgs/PoseStamped",
                      lambda seq: fs.pose_stamped(seq, ns, self.map_frame, pose), ns)

    def plan(self, t: float, poses: Sequence[Pose], *, topic: str = PLAN_TOPIC,
             frame_id: str | None = None) -> None:
        """A global plan as nav_msgs/Path (each pose (x, y, yaw) in ``frame_id``, default the
        map frame), as move_base's planner publishes it: for a navigation stack to call."""
        ns = to_ns(t)
        frame = frame_id or self.map_frame
        self.pub.send(topic, "nav_msgs/Path", lambda seq: fs.path(seq, ns, frame, poses), ns)

    def depth_image(self, frame: Any, camera: Any) -> None:
        """/<camera>/depth/image_raw (16UC1 [mm]) of a ``CameraFrame``."""
        ns = to_ns(frame.stamp)
        self.pub.send(f"/{camera.name}/depth/image_raw", "sensor_msgs/Image",
                      lambda seq: fs.image(seq, ns, camera.optical_frame_id, "16UC1",
                                           frame.depth), ns)


class WorldFeed:
    """Writes a ``WorldSim``'s topics after each of its steps (see the module docstring).
    Made by :meth:`RunPublisher.attach_world`; ``close()`` writes the last tick's scan and
    gives the world its own ``_after_step`` back."""

    def __init__(self, topics: WorldTopics, world: Any) -> None:
        from lowerbase.world.lidar import LidarRig

        self.topics, self.world = topics, world
        lidars = [dataclasses.replace(lc, seed=lc.seed + NOISE_SEED_OFFSET)
                  for lc in world.sensors.lidars]
        self.rig = LidarRig(lidars, world.sensors.scan)
        self.own_scans = 0  #: ticks the feed cast itself (the world had not)
        self._tick: tuple[float, Any] | None = None
        self._scan: Any = None  #: the world's scan of the current tick, once it cast it
        self._estimate = world.estimate
        self._frame = world.frame
        self._closed = False
        topics.map(world.now, world.grid)
        # after every step and every batch of periods (WorldSim.run_periods), which both end
        # in the world's _after_step; a batch never runs past a scan tick
        self._world_after = world._after_step
        world._after_step = self.after_step

    def after_step(self) -> None:
        """The world's own bookkeeping after a step or a batch, then what it made."""
        self._world_after()
        self._after()

    def _after(self) -> None:
        w, topics = self.world, self.topics
        tick = w._tick  # (t, true map pose) of the last scan tick (WorldSim internal)
        if tick is not None and tick is not self._tick:
            self._finish()
            self._tick, self._scan = tick, None
            t, pose = tick
            topics.latch_map()
            topics.truth_pose(t, pose)
            if w.map_to_odom is not None:
                topics.map_to_odom(t, w.map_to_odom)
        cast = w._scan  # the tick's scan once the world cast it (internal)
        if cast is not None and self._tick is not None and cast.stamp == self._tick[0]:
            self._scan = cast
        if w.estimate is not self._estimate:
            self._estimate = w.estimate
            if w.estimate is not None:
                topics.amcl_pose(w.now, w.estimate)
        if w.frame is not self._frame:
            self._frame = w.frame
            if w.frame is not None and w.camera is not None:
                topics.depth_image(w.frame, w.camera.config)

    def _finish(self) -> None:
        """The current tick's /scan: the world's if it cast it, else the feed's own."""
        if self._tick is None:
            return
        scan = self._scan
        if scan is None and self.topics.wants_scan():
            t, pose = self._tick
            scan = self.rig.scan(self.world.scene_at(t), pose, t)
            self.own_scans += 1
        if scan is not None:
            self.topics.scan(scan)
        self._tick = self._scan = None

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._finish()
        if self.world._after_step == self.after_step:
            del self.world._after_step  # the class's method again


def world_topics(publisher: RunPublisher) -> WorldTopics:
    """The :class:`WorldTopics` on ``publisher``'s sinks (made once; e.g. ``.plan(t, poses)``)."""
    if publisher.world_topics is None:
        publisher.world_topics = WorldTopics(publisher)
    topics: WorldTopics = publisher.world_topics
    return topics


def attach_world(publisher: RunPublisher, world: Any) -> WorldFeed:
    """Write a ``lowerbase.world.sim.WorldSim``'s topics on ``publisher`` as it steps (/map,
    /scan, /amcl_pose, map -> odom, the truth on the map); the feed is closed with the
    publisher."""
    feed = WorldFeed(world_topics(publisher), world)
    publisher.add_feed(feed)
    return feed
