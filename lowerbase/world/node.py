"""The world as a ROS1 node (``lowerbase world``): sensors and localization of the chassis.

A thin rospy layer, as ``lowerbase.driver.node``: :class:`WorldSetup` (ROS-free, checked before
rospy starts: :mod:`lowerbase.world.node_setup`) holds the map, places, obstacles, sensors and
the robot's start pose;
:class:`WorldNode` reads the emulator's ground truth (a :class:`~lowerbase.world.truth.TruthSource`,
in a process of its own: :class:`~lowerbase.world.truth_stream.TruthReceiver`), casts the
lidars and renders the camera at the truth's pose, runs the
:class:`~lowerbase.world.localization.Localizer` on /scan and the driver's /odom, and serves the
vendor's interface (docs/world.md, "ROS interface"; the subscribers and services:
:mod:`lowerbase.world.node_inputs`).

Threads: the main loop (sensors, localization, TF) and rospy's callback threads (/odom,
/initialpose, services) share one lock. Stamps are rospy's time (sim time from /clock under
/use_sim_time, e.g. ``--publish-clock``: :mod:`lowerbase.world.sim_clock`); obstacles move on the
emulator's time (the truth sample's ``t``). Bad input (a NaN pose, a malformed map) is a failed
service response or a logged drop, never an exception out of a callback.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Sequence
from typing import Any

from lowerbase.clock import Clock, RealClock
from lowerbase.errors import LowerbaseError
from lowerbase.ros1.wire import wanted
from lowerbase.world.camera import DepthCamera
from lowerbase.world.lazy_scan import LazyScan
from lowerbase.world.lidar import LaserScan, LidarRig
from lowerbase.world.localization import Localizer
from lowerbase.world.localization.lostwatch import LOCALIZED, LostWatch
from lowerbase.world.localization.poses import compose
from lowerbase.world.node_inputs import WorldInputs
from lowerbase.world.node_setup import Pose, WorldSetup
from lowerbase.world.pacing import RateWatch, RosPace, pace_for, paced_loop
from lowerbase.world.raycast import Scene, Solid
from lowerbase.world.scan_odom import ScanOdom
from lowerbase.world.sim_clock import TruthTime
from lowerbase.world.truth import PeopleFromTruth, WorldSurroundings

log = logging.getLogger(__name__)

NODE_NAME = "world"
#: the truth is stale (emulator stopped) after this long without a sample [s]
TRUTH_TIMEOUT = 1.0


def import_ros() -> tuple[Any, Any]:
    """(rospy, lowerbase.world.ros_msgs); RosUnavailableError in one line if missing."""
    from lowerbase.errors import RosUnavailableError
    from lowerbase.ros1.node import ROS_HINT

    try:
        import rospy

        from lowerbase.world import ros_msgs
    except ImportError as exc:
        raise RosUnavailableError(f"ROS is not installed ({exc}): {ROS_HINT}") from None
    return rospy, ros_msgs


class WorldNode(WorldInputs):
    """Publishers, subscribers, services and the sensor loop around one WorldSetup (the
    subscribers and services: :class:`~lowerbase.world.node_inputs.WorldInputs`)."""

    def __init__(self, setup: WorldSetup, truth: Any, *, clock: Clock | None = None,
                 wire: Any = None, lock: Any = None, ros: tuple[Any, Any] | None = None) -> None:
        """``clock``: the localizer's (None: wall time); ``wire``: how the face reaches ROS
        (:mod:`lowerbase.ros1.wire`; None: rospy as is); ``lock``: shared with the other faces
        of this process (None: one of its own); ``ros``: (rospy or a stand-in, the message
        builders) in place of :func:`import_ros`'s (ROS 2: :mod:`lowerbase.robot.
        lockstep_ros2`)."""
        from lowerbase.ros1.wire import RosWire

        self.rospy, self.io = ros if ros is not None else import_ros()
        self.wire = wire if wire is not None else RosWire(self.rospy)
        self.setup = setup
        self.truth = truth
        self.lock = lock if lock is not None else threading.RLock()
        self.stop = threading.Event()
        self.scene = Scene(setup.grid)
        self.lidars = LidarRig(setup.sensors.lidars, setup.sensors.scan)
        cam = setup.sensors.camera
        self.camera = DepthCamera(cam) if (cam is not None and setup.camera) else None
        self.served_map = setup.grid  #: what /map and get_map serve (set_map replaces it)
        #: the people's waits, decided from every truth sample this node receives (the
        #: emulator's contact decides its own from every period: people.py, docs/world.md)
        self.people = PeopleFromTruth(
            WorldSurroundings(setup.grid, setup.obstacles, map_from_truth=setup.start),
            truth) if setup.obstacles.people else None
        self.localizer = Localizer(setup.grid, clock=clock or RealClock(self.stop),
                                   seed=setup.seed,
                                   initial_pose=setup.start, truth=self._true_map_pose,
                                   ground_truth=setup.ground_truth)
        self.lost_watch = LostWatch()  #: says when the estimate turns lost or found again
        self.odom: Pose | None = None
        self.scan_odom = ScanOdom()  #: each scan with /odom at its stamp, for the localizer
        self.stats: dict[str, int] = {"scans": 0, "scans_cast": 0, "frames": 0, "bad_odom": 0,
                                      "bad_initialpose": 0, "amcl_poses": 0}
        self._watches: dict[str, RateWatch] = {}  #: the loops' by name (camera, lidar)
        self._pubs: dict[str, Any] = {}
        self._subs: list[Any] = []
        self._services: list[Any] = []
        self._tf: Any = None
        self._static: Any = None
        self._truth_state = "waiting"

    # -- the truth -----------------------------------------------------------------------------
    def _true_map_pose(self) -> Pose:
        sample = self.truth.sample()
        if sample is None:
            return (math.nan, math.nan, math.nan)
        return compose(self.setup.start, sample.pose)

    # -- set-up --------------------------------------------------------------------------------
    def advertise(self) -> None:
        rospy, io, wire = self.rospy, self.io, self.wire
        pub = wire.publisher
        self._pubs = {"scan": pub("/scan", io.LaserScan, queue_size=5),
                      "amcl_pose": pub("/amcl_pose", io.PoseWithCovarianceStamped,
                                       queue_size=5, latch=True),
                      "pose2d": pub("movebase_pose2d", io.Pose2D, queue_size=5),
                      "localization": pub("lowerbase/localization", io.String, queue_size=2,
                                          latch=True),
                      "map": pub("/map", io.GridMsg, queue_size=1, latch=True)}
        if self.camera is not None:
            name = self.camera.config.name
            self._pubs.update({
                "color": pub(f"/{name}/color/image_raw", io.Image, queue_size=2),
                "color_info": pub(f"/{name}/color/camera_info", io.CameraInfo, queue_size=2),
                "depth": pub(f"/{name}/depth/image_raw", io.Image, queue_size=2),
                "depth_info": pub(f"/{name}/depth/camera_info", io.CameraInfo, queue_size=2),
                "points": pub(f"/{name}/depth/points", io.PointCloud2, queue_size=2),
                "no_planes": pub(f"/{name}/depth/cloud_without_planes", io.PointCloud2,
                                 queue_size=2)})
        self._tf = wire.tf_broadcaster()
        self._static = wire.static_broadcaster()
        self._static.sendTransform(self.static_transforms(rospy.Time.now()))
        self._publish_map()
        self._subs, self._services = self.listen()

    def static_transforms(self, stamp: Any) -> list[Any]:
        """base_link -> each lidar frame, -> camera link -> its optical frames (REP-103/105)."""
        io, base = self.io, self.setup.base_frame
        out = [io.transform(stamp, base, lc.frame_id, (lc.x, lc.y, lc.z),
                            io.yaw_quaternion(lc.yaw)) for lc in self.setup.sensors.lidars]
        cam = self.setup.sensors.camera
        if cam is not None and self.camera is not None:
            out.append(io.transform(stamp, base, cam.frame_id, (cam.x, cam.y, cam.z),
                                    io.rpy_quaternion(0.0, cam.pitch, cam.yaw)))
            for optical in sorted({cam.optical_frame_id, self.color_frame}):
                out.append(io.transform(stamp, cam.frame_id, optical, (0.0, 0.0, 0.0),
                                        io.OPTICAL))
        return out

    @property
    def color_frame(self) -> str:
        cam = self.setup.sensors.camera
        return f"{cam.name}_color_optical_frame" if cam is not None else ""

    def _publish_map(self) -> None:
        self._pubs["map"].publish(self.io.grid_msg(self.served_map, self.rospy.Time.now(),
                                                   self.setup.map_frame))

    # -- world -> ROS --------------------------------------------------------------------------
    def _pose_now(self) -> tuple[Pose, float] | None:
        """The true map pose and the emulator's time, or None without a fresh truth."""
        sample = self.truth.sample()
        fresh = sample is not None and getattr(self.truth, "age", lambda: 0.0)() < TRUTH_TIMEOUT
        state = "ok" if fresh else ("stale" if sample is not None else "waiting")
        if state != self._truth_state:
            self._truth_state = state
            print({"ok": "lowerbase world: ground truth received, sensors on",
                   "stale": "lowerbase world: the ground truth stopped (emulator gone?); "
                            "sensors paused"}.get(state, ""), flush=True)
        if not fresh or sample is None:
            return None
        if self.people is not None:
            self.people.read(sample)
        return compose(self.setup.start, sample.pose), sample.t

    def scene_at(self, t: float) -> Scene:
        prisms = self.setup.obstacles.prisms_at(t)
        return self.scene.with_solids(Solid(p.height, p.polygon, p.circle) for p in prisms)

    def scan_once(self) -> None:
        now = self._pose_now()
        if now is None:
            return
        pose, t = now
        stamp = self._stamp_of(t)
        with self.lock:
            if not self.scan_odom.fresh(stamp.to_sec()):
                return  # a second scan in one /clock step (a catch-up): the same instant
        # The scan's random numbers now, its ray cast when first read (LazyScan): alone, or
        # with /scan taken outside, at once; in lockstep with no outside reader only the
        # scans navigation's costmap and the localizer read are ever cast.
        rig, scene, draws = self.lidars, self.scene_at(t), self.lidars.draw()
        scan = LazyScan(rig.merger.merged.frame_id, t,
                        lambda: self._cast(rig.scan(scene, pose, t, draws)))
        io = self.io  # in-process, navigation takes the scan as it would read it back
        received = LazyScan(scan.frame_id, stamp.to_sec(),
                            lambda: io.scan_as_received(scan.scan(), stamp))
        self.wire.publish_lazy(self._pubs["scan"], io.header(stamp, scan.frame_id),
                               lambda: io.laser_scan(scan.scan(), stamp),
                               {io.SCAN: lambda: received})
        self.stats["scans"] += 1
        with self.lock:
            self.scan_odom.add_scan(stamp.to_sec(), scan)
            self._localize()

    def _cast(self, scan: LaserScan) -> LaserScan:
        self.stats["scans_cast"] += 1
        return scan

    def _stamp_of(self, t: float) -> Any:
        """The ROS stamp of the truth sample at emulator time ``t``: its own /clock time under
        ``--publish-clock`` (rospy's newest /clock may be a step behind), else now."""
        clock = getattr(self.truth, "time", None)
        if isinstance(clock, TruthTime) and clock.last_t is not None:
            return self.rospy.Time.from_sec(t + clock.offset)
        return self.rospy.Time.now()

    def _localize(self) -> None:
        """The localizer on each scan /odom has reached, with /odom at the scan's stamp (as
        amcl's message filter); map -> odom and /amcl_pose stamped with that scan's stamp."""
        s, io = self.setup, self.io
        for at, odom, scan in self.scan_odom.ready():
            stamp = self.rospy.Time.from_sec(at)
            est = self.localizer.update(odom, scan)
            if est is not None:
                if wanted(self._pubs["amcl_pose"]):  # nobody takes it: not built
                    self._pubs["amcl_pose"].publish(io.pose_with_covariance(
                        stamp, s.map_frame, est.pose, est.covariance))
                self.stats["amcl_poses"] += 1
                line = self.lost_watch.update(est)
                if line is not None:
                    (log.info if line == LOCALIZED else log.warning)("localization %s", line)
                    self._pubs["localization"].publish(io.String(data=line))
            m2o = self.localizer.map_to_odom
            if m2o is None:
                continue
            self._tf.sendTransform(io.transform_2d(stamp, s.map_frame, s.odom_frame, m2o))
            if self.localizer.running and self.odom is not None \
                    and wanted(self._pubs["pose2d"]):  # nobody takes it: not built
                self._pubs["pose2d"].publish(io.pose_2d(compose(m2o, self.odom)))

    def frame_once(self) -> None:
        now = self._pose_now()
        if now is None or self.camera is None:
            return
        pose, t = now
        stamp = self._stamp_of(t)  # the rendering pose's time, as the scans'
        f = self.camera.render(self.scene_at(t), pose, t)
        io, cfg = self.io, self.camera.config
        self._pubs["color"].publish(io.image(f.color, "rgb8", self.color_frame, stamp))
        self._pubs["color_info"].publish(io.camera_info(cfg, self.color_frame, stamp))
        self._pubs["depth"].publish(io.image(f.depth, "16UC1", cfg.optical_frame_id, stamp))
        self._pubs["depth_info"].publish(io.camera_info(cfg, cfg.optical_frame_id, stamp))
        self._pubs["points"].publish(io.cloud_xyz32(f.points, cfg.optical_frame_id, stamp))
        self._pubs["no_planes"].publish(io.cloud_xyz32(f.points_without_planes,
                                                       cfg.optical_frame_id, stamp))
        self.stats["frames"] += 1

    def spin(self) -> None:
        """Scans at the lidars' rate in this thread, camera frames at the camera's rate in a
        thread of its own (numpy releases the GIL: the two share the cores), until rospy
        shuts down. Rates are per second of ROS time: sim time under /use_sim_time, where a
        late scan is caught up (within 1 s: each simulated tick is scanned). On wall time a
        late scan, like a late frame, is dropped and counted, as a real lidar's missed
        revolution is never sent later (a catch-up would send scans of one pose with stamps
        bunched together)."""
        rospy = self.rospy
        rospy.on_shutdown(self.stop.set)
        camera = None
        if self.camera is not None:
            camera = threading.Thread(target=self._loop, name="world-camera", daemon=True,
                                      args=(self.frame_once, self.camera.config.rate_hz, False,
                                            "camera"))
            camera.start()
        self._loop(self.scan_once, self.lidars.rate_hz, True, "lidar")
        if camera is not None:
            camera.join(timeout=5.0)

    def _loop(self, work: Any, rate_hz: float, catch_up: bool, name: str) -> None:
        """``work`` at ``rate_hz`` per second of ROS time under /use_sim_time (woken by
        /clock), else of wall time (lowerbase.world.pacing); ``catch_up``: late ticks are
        caught up under /use_sim_time (on wall time they are dropped, counted)."""
        def running() -> bool:
            return not self.stop.is_set() and not self.rospy.is_shutdown()

        pace = pace_for(self.rospy, self.stop)
        catch_up = catch_up and isinstance(pace, RosPace)
        watch = RateWatch(name, rate_hz)  # the dropping loop says what rate it keeps
        self._watches[name] = watch

        def guarded() -> None:
            try:
                work()
            except LowerbaseError as exc:  # e.g. a camera mounted above the walls
                log.error("%s; stopping this sensor", exc)
                failed.set()
                return
            if not catch_up:
                watch.done_and_warn(pace.now(), log)

        failed = threading.Event()
        paced_loop(pace, guarded, rate_hz, catch_up, lambda: running() and not failed.is_set(),
                   watch.dropped)

    @property
    def frames_dropped(self) -> int:
        """Camera frames dropped so far (their loop could not keep its rate): the stop line's
        ``frames_dropped``, counted once, by the loop's :class:`RateWatch`."""
        return self._dropped("camera")

    @property
    def scans_dropped(self) -> int:
        """Scans dropped on wall time (the lidar loop could not keep its rate): the stop
        line's ``scans_dropped``."""
        return self._dropped("lidar")

    def _dropped(self, name: str) -> int:
        watch = self._watches.get(name)
        return watch.total_dropped if watch is not None else 0

    def shutdown(self) -> None:
        self.stop.set()
        for sub in self._subs:
            sub.unregister()
        for service in self._services:
            service.shutdown()


def run(setup: WorldSetup, truth: Any, ros_args: Sequence[str], truth_where: str) -> int:
    """Start rospy on the master in ROS_MASTER_URI, build the node and spin."""
    from lowerbase.ros1.node import ros_session

    import_ros()  # one line if ROS or the message modules are missing
    with ros_session("world", NODE_NAME, ros_args) as session:
        start_clock = getattr(truth, "start_ros", None)
        if start_clock is not None:  # --publish-clock: /clock from the truth (world.sim_clock)
            start_clock(session.rospy)
        node = WorldNode(setup, truth)
        try:
            node.advertise()
            session.announce(f"ground truth from {truth_where}")
            node.spin()
        finally:
            node.shutdown()
            session.stopped({**node.stats, "frames_dropped": node.frames_dropped,
                             "scans_dropped": node.scans_dropped, **node.scan_odom.counts})
    return 0
