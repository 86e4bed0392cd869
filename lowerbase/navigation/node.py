"""Navigation as a ROS1 node (``lowerbase navigation``): move_base, step control, modes.

A thin rospy/actionlib layer over the ROS-free core, as ``lowerbase.world.node``:
:class:`NavigationSetup` (checked before rospy starts) holds the map and the costmap
parameters; :class:`NavigationNode` feeds the :class:`~lowerbase.navigation.navigator.Navigator`
and the :class:`~lowerbase.navigation.steps.StepController` from /scan, the camera's
cloud_without_planes, /odom, TF map -> odom (the world node's localization) and
/driver_base/parameter, and sends their twists to /base_cmd_vel at 20 Hz while either is
active. The action servers are in :mod:`lowerbase.navigation.actions`, the services in
:mod:`lowerbase.navigation.services`.

Threads: the main loop (one control tick per period, costmap publishing), rospy's callback
threads (subscribers, services) and actionlib's goal threads share one lock. Bad input (a NaN
pose, a malformed cloud, a bad polygon) is a failed service/action result or a counted, logged
drop, never an exception out of a callback.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from lowerbase.errors import ConfigError, LowerbaseError, WorldError, count_drop
from lowerbase.navigation.controller import Limits
from lowerbase.navigation.costmap import camera_cloud
from lowerbase.navigation.loop import control_loop
from lowerbase.navigation.steps import StepController
from lowerbase.navigation.tf_map import MapToOdom
from lowerbase.ros1.wire import wanted
from lowerbase.world.camera import CameraConfig
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lazy_scan import LazyScan, resolve
from lowerbase.world.lidar import LaserScan
from lowerbase.world.localization.poses import compose
from lowerbase.world.pacing import Pace, RateWatch
from lowerbase.world.stamped import PoseHistory, StampedSensors

log = logging.getLogger(__name__)

NODE_NAME = "move_base"
Pose = tuple[float, float, float]
#: commands are sent this many periods after both controllers went idle (zeros: a clean stop)
STOP_TAIL = 5
#: observations held per sensor for /odom and TF to reach their stamp (costmap_2d's tf filter
#: queue: 50, 2 s of 25 Hz scans), and the longest wait for TF map -> odom there [s of /odom]
#: (/odom reached the nodes up to 2.5 s late at K=2 on a loaded host: docs/robot.md)
SENSOR_DEPTH, SENSOR_TF_WAIT = 50, 2.0


@dataclass
class NavigationSetup:
    """Everything the node needs, checked without ROS (see ``lowerbase.cli.navigation``)."""

    grid: OccupancyGrid
    camera: CameraConfig | None = None
    navigator: Any = None  #: a NavigatorConfig (None: move_base's defaults, docs/navigation.md)
    map_frame: str = "map"
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    rate_hz: float = 20.0  #: control rate (/base_cmd_vel while active) [Hz]
    costmap_rate_hz: float = 2.0  #: the local costmap's publishing rate [Hz]
    #: the local costmap's ``update_frequency`` [Hz]: each update marks and clears the newest
    #: scan (and cloud) whose stamp /odom and TF have reached, as costmap_2d's observation
    #: buffers with ``observation_keep_time`` 0; a tick between updates only steers
    update_rate_hz: float = 5.0

    def __post_init__(self) -> None:
        for name in ("rate_hz", "costmap_rate_hz", "update_rate_hz"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0 < value <= 100):
                raise ConfigError(f"{name} = {value!r}: expected a rate in (0, 100] Hz")


def import_ros() -> tuple[Any, Any]:
    """(rospy, lowerbase.navigation.ros_msgs); RosUnavailableError in one line if missing."""
    from lowerbase.errors import RosUnavailableError
    from lowerbase.ros1.node import ROS_HINT

    try:
        import actionlib  # type: ignore[import-untyped]  # noqa: F401
        import rospy

        from lowerbase.navigation import ros_msgs
    except ImportError as exc:
        raise RosUnavailableError(f"ROS is not installed ({exc}): {ROS_HINT}") from None
    return rospy, ros_msgs


def make_navigator(setup: NavigationSetup) -> Any:
    from lowerbase.navigation.navigator import Navigator

    return Navigator(setup.grid, setup.navigator)


class NavigationNode:
    """Subscribers, publishers, services and the control loop around one Navigator."""

    def __init__(self, setup: NavigationSetup, *, wire: Any = None, lock: Any = None,
                 ros: tuple[Any, Any] | None = None) -> None:
        """``wire``: how the face reaches ROS (:mod:`lowerbase.ros1.wire`; None: rospy as is);
        ``lock``: shared with the other faces of this process (None: one of its own);
        ``ros``: (rospy or a stand-in, the message builders) in place of :func:`import_ros`'s
        (ROS 2: :mod:`lowerbase.robot.lockstep_ros2`)."""
        from lowerbase.ros1.wire import RosWire

        self.rospy, self.io = ros if ros is not None else import_ros()
        self.wire = wire if wire is not None else RosWire(self.rospy)
        self.setup = setup
        self.lock = lock if lock is not None else threading.RLock()
        self.ticked = threading.Condition(self.lock)  #: notified after every control tick
        self.stop = threading.Event()
        self.navigator = make_navigator(setup)
        self.steps = StepController(period=1.0 / setup.rate_hz)
        self.limits = Limits()
        self.odom: Pose | None = None
        self.odom_stamp: float | None = None  #: /odom's header stamp [s, ROS time]
        self.map_to_odom: Pose | None = None
        self.scan: LaserScan | LazyScan | None = None  #: the newest /scan (cast when read)
        self.scan_stamp: float | None = None  #: its header stamp [s, ROS time]
        #: /odom's poses by stamp, and the scans and clouds waiting for it to reach theirs
        self.odom_history = PoseHistory()
        self.tf = MapToOdom(self.rospy, setup.map_frame, setup.odom_frame)
        self.sensors = StampedSensors(self.odom_history, self.tf.at, SENSOR_DEPTH,
                                      tf_newest=self.tf.newest, wait=SENSOR_TF_WAIT)
        self.last_command: Any = None  #: the Navigator's NavCommand of the last tick
        self.tick_count = 0
        #: ticks per local costmap update (the first tick updates)
        self._update_every = max(1, round(setup.rate_hz / setup.update_rate_hz))
        self.stats: dict[str, int] = {"bad_scan": 0, "bad_cloud": 0, "bad_odom": 0,
                                      "bad_footprint": 0, "bad_parameter": 0, "no_pose": 0,
                                      "cmd_vel": 0, "plans": 0, "superseded": 0}
        self._tail = 0
        #: the control loop's rate on wall time: ticks missed on a busy host (``ticks_missed``)
        self.control_watch = RateWatch("move_base control loop", setup.rate_hz, what="tick")
        self.pubs: dict[str, Any] = {}
        self._subs: list[Any] = []
        self._services: list[Any] = []
        self._servers: Any = None
        self._published_global: Any = None
        self._ready_printed = False
        self._plans_published = 0
        self.pace: Pace | None = None  #: set on the master (advertise): wall or ROS time

    # -- time ----------------------------------------------------------------------------------
    def now(self) -> float:
        """[s] the node's clock: ROS time (/clock's) under /use_sim_time, else monotonic wall
        time; every deadline of the Navigator and the StepController is on it."""
        return self.pace.now() if self.pace is not None else time.monotonic()

    # -- set-up --------------------------------------------------------------------------------
    def advertise(self) -> None:
        rospy, io, wire = self.rospy, self.io, self.wire
        from lowerbase.world.pacing import pace_for

        self.pace = pace_for(rospy, self.stop)
        from geometry_msgs.msg import Polygon
        from nav_msgs.msg import Odometry
        from nav_msgs.srv import GetPlan
        from sensor_msgs.msg import LaserScan as ScanMsg
        from sensor_msgs.msg import PointCloud2
        from std_srvs.srv import Empty, SetBool  # type: ignore[import-untyped]
        from woosh_msgs.msg import Parameter

        from lowerbase.navigation.actions import ActionServers
        from lowerbase.navigation.services import Services

        self.tf.listen(wire.tf_buffer())
        pub = wire.publisher
        self.pubs = {
            "cmd_vel": pub("base_cmd_vel", io.Twist, queue_size=5),
            "global": pub("~global_costmap/costmap", io.GridMsg, queue_size=1, latch=True),
            "local": pub("~local_costmap/costmap", io.GridMsg, queue_size=1),
            "plan": pub("~NavfnROS/plan", io.Path, queue_size=1, latch=True),
        }
        sub = wire.subscriber
        self._subs = [
            sub("scan", ScanMsg, self._on_scan, queue_size=2),
            sub("odom", Odometry, self._on_odom, queue_size=10),
            sub("driver_base/parameter", Parameter, self._on_parameter, queue_size=2),
            sub("~local_costmap/set_footprint", Polygon,
                lambda m: self._on_footprint(m, "local"), queue_size=2),
            sub("~global_costmap/set_footprint", Polygon,
                lambda m: self._on_footprint(m, "global"), queue_size=2),
        ]
        if self.setup.camera is not None:
            self._subs.append(sub(f"{self.setup.camera.name}/depth/cloud_without_planes",
                                  PointCloud2, self._on_cloud, queue_size=1, buff_size=2 ** 24))
        services = Services(self)
        self._services = [wire.service("~make_plan", GetPlan, services.make_plan),
                          wire.service("~enable_costmaps", SetBool, services.enable),
                          wire.service("~clear_costmaps", Empty, services.clear)]
        self._servers = ActionServers(self)
        self._servers.start()

    # -- ROS -> navigation ---------------------------------------------------------------------
    def _count_bad(self, key: str, exc: Exception) -> None:
        count_drop(self.stats, key, log, exc)

    def _on_odom(self, msg: Any) -> None:
        try:
            pose = self.wire.convert(msg, self.io.ODOM_POSE, self.io.odom_pose)
        except WorldError as exc:
            self._count_bad("bad_odom", exc)
            return
        stamp = msg.header.stamp.to_sec()
        with self.lock:
            self.odom = pose
            self.odom_stamp = stamp if stamp > 0 else None  # StepControl: a stalled /odom
            self.odom_history.add(self._stamp(stamp), pose)

    def _stamp(self, stamp: float) -> float:
        """A header stamp [s]; an unset one (0) is taken as now (ROS time)."""
        return stamp if stamp > 0 else float(self.rospy.get_time())

    def _on_scan(self, msg: Any) -> None:
        try:
            scan = self.wire.convert(msg, self.io.SCAN, self.io.scan_of)
            if scan.frame_id.lstrip("/") != self.setup.base_frame:
                raise WorldError(f"/scan must be in {self.setup.base_frame!r} (the merged "
                                 f"scan), got {scan.frame_id!r}")
        except WorldError as exc:
            self._count_bad("bad_scan", exc)
            return
        stamp = self._stamp(msg.header.stamp.to_sec())
        with self.lock:
            self.scan = scan
            self.scan_stamp = stamp
            self.sensors.add("scan", stamp, scan)

    def _on_cloud(self, msg: Any) -> None:
        camera = self.setup.camera
        assert camera is not None
        try:
            if msg.header.frame_id.lstrip("/") != camera.optical_frame_id:
                raise WorldError(f"cloud_without_planes must be in {camera.optical_frame_id!r},"
                                 f" got {msg.header.frame_id!r}")
            cloud = camera_cloud(self.io.cloud_points(msg), camera)
        except WorldError as exc:
            self._count_bad("bad_cloud", exc)
            return
        stamp = self._stamp(msg.header.stamp.to_sec())
        with self.lock:
            self.sensors.add("cloud", stamp, cloud)

    def _on_parameter(self, msg: Any) -> None:
        try:
            limits = Limits.from_parameters({"maxLinear": float(msg.maxLinear),
                                             "maxAngular": float(msg.maxAngular)})
        except LowerbaseError as exc:
            self._count_bad("bad_parameter", exc)
            return
        with self.lock:
            self.limits = limits
            self.steps.limits = limits
            self.navigator.set_limits(limits)

    def _on_footprint(self, msg: Any, which: str) -> None:
        """The seed's set_footprint topics: each changes its own costmap; the global one is
        also the footprint the planner and the controller check (Navigator.set_footprint)."""
        try:
            points = self.io.polygon_points(msg)
            with self.lock:
                self.navigator.set_footprint(points, which)
        except WorldError as exc:
            self._count_bad("bad_footprint", exc)
            return
        log.info("%s costmap footprint set: %d points", which, len(points))

    # -- the robot's pose ----------------------------------------------------------------------
    def _lookup_map_to_odom(self) -> None:
        m2o = self.tf.latest()
        if m2o is not None:
            with self.lock:
                self.map_to_odom = m2o

    def map_pose(self) -> Pose | None:
        """The robot in the map frame: TF map -> odom (localization) composed with /odom."""
        with self.lock:
            if self.odom is None or self.map_to_odom is None:
                return None
            return compose(self.map_to_odom, self.odom)

    def _sensed(self) -> float | None:
        """[s] the older of the newest /scan and the newest map -> odom (the Navigator stops
        when it is out of date); None before the first scan (a robot without one)."""
        if self.scan_stamp is None:
            return None
        localized = self.tf.newest()
        return self.scan_stamp if localized is None else min(self.scan_stamp, localized)

    # -- the loop ------------------------------------------------------------------------------
    def tick(self, now: float | None = None) -> None:
        """One control period at ``now`` (None: :meth:`now`): sensors into the costmaps, one
        twist if anything is active."""
        self._lookup_map_to_odom()
        if now is None:
            now = self.now()
        with self.lock:
            pose = self.map_pose()
            if self.tick_count % self._update_every == 0:
                self._update_costmap()
            command: tuple[float, float] | None = None
            if self.steps.active:
                command = self.steps.tick(self.odom, now, self.odom_stamp) \
                    if self.odom is not None else (0.0, 0.0)
            elif self.navigator_active():
                if pose is None:
                    self.stats["no_pose"] += 1
                    command = (0.0, 0.0)
                else:
                    cmd = self.navigator.tick(now, pose, self._sensed())
                    self.last_command = cmd
                    command = (cmd.linear, cmd.angular)
                    if self.navigator.plans != self._plans_published:
                        self._plans_published = self.navigator.plans
                        self.pubs["plan"].publish(self.io.path_msg(
                            self.navigator.path, self.rospy.Time.now(), self.setup.map_frame))
            if command is not None:
                self._tail = STOP_TAIL
            elif self._tail > 0:  # both idle: a few zeros, then silence (others may command)
                self._tail -= 1
                command = (0.0, 0.0)
            if command is not None:
                self.pubs["cmd_vel"].publish(self.io.twist(*command))
                self.stats["cmd_vel"] += 1
            self.tick_count += 1
            self.ticked.notify_all()
        self._ready_line(pose)

    def _update_costmap(self) -> None:
        """One local costmap update: the newest scan and cloud /odom and TF have reached,
        each at its stamp's pose; older ones since the last update are dropped unread
        (costmap_2d keeps only the newest with ``observation_keep_time`` 0)."""
        newest: dict[str, tuple[Pose, Any]] = {}
        for sensor, at, data in self.sensors.ready():  # oldest first per sensor
            if sensor in newest:
                self.stats["superseded"] += 1
            newest[sensor] = (at, data)
        try:  # a scan is cast only now, when read (lowerbase.world.lazy_scan)
            items = [(at, resolve(data), None) if sensor == "scan" else (at, None, data)
                     for sensor, (at, data) in newest.items()]
            self.navigator.update_observations(items)
        except WorldError as exc:
            self._count_bad("bad_scan", exc)

    def navigator_active(self) -> bool:
        from lowerbase.navigation.navigator import GoalState

        return self.navigator.state in (GoalState.PENDING, GoalState.ACTIVE)

    def _ready_line(self, pose: Pose | None) -> None:
        if self._ready_printed or pose is None or self.scan is None:
            return
        self._ready_printed = True
        print(f"lowerbase navigation: ready; robot at ({pose[0]:.2f}, {pose[1]:.2f}, "
              f"{pose[2]:.2f}) on the map", flush=True)

    def publish_costmaps(self, publish_local: bool) -> None:
        io, frame = self.io, self.setup.map_frame
        stamp = self.rospy.Time.now()
        with self.lock:
            gc, lc = self.navigator.global_costmap, self.navigator.local_costmap
            costs = gc.costs
            if costs is not self._published_global:
                self._published_global = costs
                self.pubs["global"].publish(io.costmap_msg(costs, gc.resolution, gc.origin,
                                                            stamp, frame))
            if publish_local and wanted(self.pubs["local"]):  # nobody takes it: not built
                self.pubs["local"].publish(io.costmap_msg(lc.costs, lc.resolution, lc.origin,
                                                           stamp, frame))

    def spin(self) -> None:
        """The control loop at ``rate_hz`` per second of the node's clock (ROS time under
        /use_sim_time, woken by /clock) until rospy shuts down."""
        rospy = self.rospy
        rospy.on_shutdown(self.stop.set)
        if self.pace is None:
            from lowerbase.world.pacing import WallPace

            self.pace = WallPace(self.stop)
        control_loop(self.pace, self.tick, self.publish_costmaps, self.setup,
                     lambda: not self.stop.is_set() and not rospy.is_shutdown(),
                     self.control_watch)

    def shutdown(self) -> None:
        self.stop.set()
        with self.lock:
            self.ticked.notify_all()
        if self._servers is not None:
            self._servers.shutdown()
        if self.pubs and (self.steps.active or self.navigator_active()):
            try:  # a last zero twist; rospy may already have closed the topic
                self.pubs["cmd_vel"].publish(self.io.twist(0.0, 0.0))
            except self.rospy.ROSException as exc:
                log.warning("no zero twist at shutdown: %s", exc)
        for sub in self._subs:
            sub.unregister()
        for service in self._services:
            service.shutdown()


def with_params(setup: NavigationSetup, get_param: Callable[[str, Any], Any]
                ) -> NavigationSetup:
    """``setup`` with move_base's private ``~recovery_behaviors`` applied when it is set: a
    list of :data:`lowerbase.navigation.recovery.BEHAVIORS` names in the order to run them
    (move_base's ``{name, type}`` entries count by their ``name``). A bad value: one
    NavigationError line."""
    from lowerbase.navigation.goals import NavigationError, NavigatorConfig

    value = get_param("~recovery_behaviors", None)
    if value is None:
        return setup
    if not isinstance(value, (list, tuple)):
        raise NavigationError(f"~recovery_behaviors must be a list of behaviour names, got "
                              f"{value!r}")
    names = tuple(v.get("name") if isinstance(v, dict) else v for v in value)
    base = setup.navigator if setup.navigator is not None else NavigatorConfig()
    return replace(setup, navigator=replace(base, recovery_behaviors=names))


def run(setup: NavigationSetup, ros_args: Sequence[str], where: str) -> int:
    """Start rospy on the master in ROS_MASTER_URI, build the node and spin."""
    from lowerbase.ros1.node import ros_session
    from lowerbase.world.pacing import RosPace

    rospy, _ = import_ros()  # one line if ROS or the message modules are missing
    with ros_session("navigation", NODE_NAME, ros_args) as session:
        node = NavigationNode(with_params(setup, rospy.get_param))
        try:
            node.advertise()
            clock = "ROS time (/use_sim_time)" if isinstance(node.pace, RosPace) \
                else "wall time"
            session.announce(f"{where}; on {clock}; waiting for /odom, /scan and TF "
                             "map -> odom")
            node.spin()
        finally:
            node.shutdown()
            session.stopped({**node.stats, **node.sensors.stats,
                             "ticks_missed": node.control_watch.total_dropped})
    return 0
