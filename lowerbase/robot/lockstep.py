"""``lowerbase robot --sim-time``: the whole robot in one process, in lockstep on one simulated
clock: :class:`LockstepRobot`.

The parts are the ones ``lowerbase robot`` starts as processes, with the same ROS faces: the
emulated lower computer and driver_base's core exchange their frames at their periods' times
(:class:`~lowerbase.simloop.loop.SimLoop`, the MCU's 5 ms period), and driver_base's face
(:class:`~lowerbase.driver.node.DriverNode`), the world's (:class:`~lowerbase.world.node.
WorldNode`: lidars, camera, amcl, the map), navigation's (:class:`~lowerbase.navigation.node.
NavigationNode`: move_base, step control, costmaps) and the tasks' (:class:`~lowerbase.tasks.
node.TasksNode`: exec_task, robot_status) publish, subscribe and serve under the names they have
alone. What one part publishes reaches the others in this process at once
(:mod:`lowerbase.ros1.wire`), so nothing is late or lost however busy the host is; tasks drive
navigation directly (:mod:`lowerbase.tasks.local_nav`).

Each period of the MCU the parts whose rate is due run, in a fixed order (/clock at 100 Hz,
tasks, navigation, costmaps, driver_base's periodic topics, the scan, the camera frame), then
the lower computer and the driver core step 5 ms. ROS time is the simulated time
(``rospy.rostime._set_rostime``; this process does not follow its own /clock), so every stamp
is the simulated instant it describes. Nothing here sleeps or reads the wall clock: the pace
is :mod:`lowerbase.robot.simcontrol`'s.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from lowerbase.robot.plan import UPPER
from lowerbase.world.maps import DEFAULT_MAP

CLOCK_RATE = 100.0  #: [Hz] of simulated time: /clock, at the IMU's rate (the fastest sensor)
#: [Hz] actionlib's status rate where ``actionlib_status_frequency`` is not set (its default)
STATUS_HZ = 5.0
NODE = "lowerbase_robot"  #: this process' node name (the faces keep their own names)
UNTIL = ("", "move_base", "task")  #: the conditions a step can stop at (simcontrol)


@dataclass(frozen=True)
class LockstepOptions:
    """What ``lowerbase robot --sim-time`` builds (the options of ``lowerbase robot``)."""

    map: str = DEFAULT_MAP
    parts: tuple[str, ...] = UPPER
    soc: float | None = None
    ground_truth: bool = False
    camera: bool = False  #: the depth camera (~50 ms a frame to render)
    seed: int = 0
    truth: str | None = None  #: --truth FILE: the emulator's ground truth as CSV


def status_period(rospy: Any) -> float:
    """[s] between two statuses of this process' action servers: ``actionlib_status_frequency``
    found as actionlib finds it (searched up the namespace; 5 Hz by default)."""
    name = rospy.search_param("actionlib_status_frequency")
    hz = float(rospy.get_param(name, STATUS_HZ)) if name else STATUS_HZ
    return 1.0 / hz if hz > 0 else 1.0  # (0: no status timers; a wake a second all the same)


class RosTime:
    """Sets this process' ROS time (``rospy.rostime``) to the simulated time. rospy's setter
    also wakes every thread sleeping on ROS time, which cost more than the setting at every
    step. Those threads are actionlib's status timers (the faces' own loops do not run here:
    the lockstep runs their work), each due once per :func:`status_period`; they are woken
    once per ``wake_period`` (default: that period) of simulated time on its grid instead:
    every wake finds one status due, none is skipped, each comes less than a period after its
    time (a timer's next time is from its schedule, not from its wake)."""

    def __init__(self, rospy: Any, wake_period: float | None = None) -> None:
        import rospy.rostime as rostime

        if wake_period is None:
            wake_period = status_period(rospy)
        self.rospy, self.rostime, self.wake_period = rospy, rostime, wake_period
        self._wake_next = -math.inf  #: [s] the simulated time the sleepers are woken next

    def set(self, now: float) -> None:
        t = self.rospy.Time.from_sec(now)
        if now + 1e-9 < self._wake_next:
            self.rostime._rostime_current = t  # what rospy's setter sets, without the wake
            return
        self.rostime._set_rostime(t)
        self._wake_next = (math.floor(now / self.wake_period + 1e-9) + 1) * self.wake_period


class Ros1Side:
    """How the lockstep robot reaches ROS 1: rospy's faces on a :class:`~lowerbase.ros1.wire.
    LocalWire` each, ROS time set by :class:`RosTime`, /clock as rosgraph_msgs/Clock. ROS 2's
    twin is :class:`lowerbase.robot.lockstep_ros2.Ros2Side`."""

    def __init__(self, rospy: Any) -> None:
        self.rospy = rospy
        self._time: RosTime | None = None

    def board(self) -> Any:
        from lowerbase.ros1.wire import Switchboard

        return Switchboard(self.rospy)

    def wire(self, board: Any, name: str) -> Any:
        from lowerbase.ros1.wire import LocalWire

        return LocalWire(self.rospy, board, name)

    def face_ros(self, face: str) -> Any:
        """What a face takes as ``ros`` (None: it imports rospy and its builders itself)."""
        return None

    def param(self, name: str, default: Any = None) -> Any:
        """A parameter of the ROS parameter server (a global name)."""
        return self.rospy.get_param(name, default)

    def set_time(self, now: float) -> None:
        if self._time is None:
            self._time = RosTime(self.rospy)
        self._time.set(now)

    def clock_publisher(self) -> Any:
        from rosgraph_msgs.msg import Clock

        return self.rospy.Publisher("/clock", Clock, queue_size=10)

    def clock_sender(self, publisher: Any) -> Callable[[float], None] | None:
        """A function publishing /clock at a time [s]; None when nobody listens."""
        from rosgraph_msgs.msg import Clock

        from lowerbase.ros1.wire import connected

        if not connected(publisher):  # nobody on ROS listens: no message is built
            return None
        rospy = self.rospy
        return lambda t: publisher.publish(Clock(clock=rospy.Time.from_sec(t)))


def move_base_params(side: Any) -> Callable[[str, Any], Any]:
    """The navigation's private parameters (``~name``) where the vendor's robot has them:
    ``/move_base/name`` (the robot here is one node; move_base is one of its faces)."""
    from lowerbase.navigation.node import NODE_NAME

    return lambda name, default: side.param(f"/{NODE_NAME}/{name.removeprefix('~')}", default)


class _Job:
    """Work due every ``period`` [s] of simulated time, on the MCU's period grid."""

    def __init__(self, name: str, period: float, dt: float, work: Callable[[], Any]) -> None:
        self.name, self.period, self.dt, self.work = name, period, dt, work
        self.n = 0
        self.due = 0  #: the MCU period it is due at

    def run_if_due(self, step: int) -> None:
        if step < self.due:
            return
        self.work()
        while self.due <= step:  # a period shorter than the MCU's runs once per period
            self.n += 1
            self.due = math.ceil(self.n * self.period / self.dt - 1e-6)


class LockstepRobot:
    """The robot's parts and their faces on one simulated clock (see the module docstring).

    ``rospy`` must be initialised (``init_node``) by the caller; :meth:`advertise` makes every
    face's topics, services and actions; :meth:`run_periods` moves time on. ``side``: how it
    reaches ROS (None: :class:`Ros1Side` on ``rospy``; ROS 2: :mod:`lowerbase.robot.
    lockstep_ros2`, with ``rospy`` its stand-in)."""

    def __init__(self, opts: LockstepOptions, rospy: Any, side: Any = None) -> None:
        from lowerbase.driver.node import DriverNode
        from lowerbase.driver.settings import load_settings
        from lowerbase.firmware_model.profile import load_profile
        from lowerbase.simloop.loop import SimLoop
        from lowerbase.world.charger import ChargerContact
        from lowerbase.world.grid import OccupancyGrid
        from lowerbase.world.maps import load_map
        from lowerbase.world.node import WorldNode, WorldSetup
        from lowerbase.world.places import load_places
        from lowerbase.world.sensors import sensors_from_profile_file
        from lowerbase.world.sim import resolve_start
        from lowerbase.world.truth import LoopTruth, WorldSurroundings

        self.opts = opts
        self.rospy = rospy
        self.side = side if side is not None else Ros1Side(rospy)
        self.lock = threading.RLock()  #: every face's: held around each period and callback
        grid: OccupancyGrid = load_map(opts.map)
        start = resolve_start(opts.map, grid, "start")
        places = load_places(opts.map, grid)
        sensors = sensors_from_profile_file()
        settings, config = load_settings({})
        profile = load_profile()
        kwargs: dict[str, Any] = {} if opts.soc is None else {"soc": opts.soc}
        self.loop = SimLoop(profile, driver_config=config, **kwargs)
        from lowerbase.world.contact_gate import ContactGate

        #: the world's walls installed in the emulator only while a move may touch them, so
        #: the periods far from every wall run compiled (as WorldSim's; the same bits)
        self.gate = ContactGate(self.loop, WorldSurroundings(grid, map_from_truth=start))
        self.dt = self.loop.control_dt
        self.board = self.side.board()
        self._hooks: list[Callable[[Any], None]] = []
        if places.charger is not None:
            self.charger: ChargerContact | None = ChargerContact(
                places.charger, start, lambda line: print(f"lowerbase robot: {line}",
                                                          flush=True))
            self._hooks.append(self.charger)
        else:
            self.charger = None
        if opts.truth:
            from lowerbase.simloop.truth import TruthLog

            self.truth_log: Any = TruthLog(opts.truth)
        else:
            self.truth_log = None

        def wire(name: str) -> Any:
            return self.side.wire(self.board, name)

        ros = self.side.face_ros
        self.driver = DriverNode(settings, config, None, core=self.loop.driver,
                                 wire=wire("driver_base"), lock=self.lock, ros=ros("driver"))
        self.world = WorldNode(WorldSetup(grid, sensors, start, ground_truth=opts.ground_truth,
                                          camera=opts.camera, seed=opts.seed),
                               LoopTruth(self.loop), clock=self.loop.clock,
                               wire=wire("world"), lock=self.lock, ros=ros("world"))
        self.navigation: Any = None
        self.tasks: Any = None
        if "navigation" in opts.parts:
            from lowerbase.navigation.node import NavigationNode, NavigationSetup, with_params

            camera = sensors.camera if opts.camera else None
            self.navigation = NavigationNode(with_params(NavigationSetup(grid, camera),
                                                         move_base_params(self.side)),
                                             wire=wire("move_base"), lock=self.lock,
                                             ros=ros("navigation"))
        if "tasks" in opts.parts:
            if self.navigation is None:
                from lowerbase.errors import ConfigError

                raise ConfigError("tasks drive through navigation: leave out both "
                                  "(--without tasks --without navigation) or neither")
            from lowerbase.tasks.local_nav import NodeNavigation, NodeSteps
            from lowerbase.tasks.node import TasksNode, TasksSetup

            self.tasks = TasksNode(TasksSetup(places), wire=wire("tasks"), lock=self.lock,
                                   nav=NodeNavigation(self.navigation),
                                   steps=NodeSteps(self.navigation),
                                   rospy=ros("tasks"))
        self._clock_pub: Any = None
        self._clock_k, self._clock_next = 0, 0.0  #: the next /clock: its index and time [s]
        self.loop.passive_listeners = True  # driver_base's face only publishes
        self.steps = 0  #: MCU periods run
        self.jobs = self._jobs()

    def _jobs(self) -> list[_Job]:
        dt = self.dt
        jobs: list[_Job] = []
        if self.truth_log is not None:  # its rows every 20 ms
            log, mcu = self.truth_log, self.loop.mcu
            jobs.append(_Job("truth", log.period, dt, lambda: log(mcu)))
        if self.tasks is not None:
            jobs.append(_Job("tasks", self.tasks.setup.config.period, dt, self.tasks.tick))
        nav = self.navigation
        if nav is not None:
            jobs.append(_Job("navigation", 1.0 / nav.setup.rate_hz, dt,
                             lambda: nav.tick(self.now)))
            jobs.append(_Job("costmaps", 1.0 / nav.setup.costmap_rate_hz, dt,
                             lambda: nav.publish_costmaps(True)))
        jobs.append(_Job("driver", 1.0 / self.loop.driver.config.command_rate, dt,
                         self.driver.publish_periodic))
        jobs.append(_Job("scan", 1.0 / self.world.lidars.rate_hz, dt, self.world.scan_once))
        if self.world.camera is not None:
            jobs.append(_Job("camera", 1.0 / self.world.camera.config.rate_hz, dt,
                             self.world.frame_once))
        return jobs

    @property
    def now(self) -> float:
        """[s] simulated time, which is ROS time here."""
        return float(self.loop.now)

    def advertise(self) -> None:
        """Every face's publishers, subscribers, services and actions; /clock."""
        self._set_ros_time()
        self._clock_pub = self.side.clock_publisher()
        with self.lock:
            self.driver.advertise()
            self.world.advertise()
            if self.navigation is not None:
                self.navigation.advertise()
            if self.tasks is not None:
                self.tasks.advertise()

    def _set_ros_time(self) -> None:
        self.side.set_time(float(self.loop.now))

    def _publish_clock(self) -> None:
        """/clock at every 10 ms of simulated time up to now (several after a batch)."""
        now = self.loop.now
        send = self.side.clock_sender(self._clock_pub)  # None: nobody listens, nothing built
        while self._clock_next <= now + 1e-9:
            if send is not None:
                send(self._clock_next)
            self._clock_k += 1
            self._clock_next = self._clock_k / CLOCK_RATE

    def run_periods(self, periods: int, until: Callable[[], bool] | None = None) -> bool:
        """Run ``periods`` MCU periods (5 ms each), the parts that are due in each; with
        ``until``, stop early at the first control period (50 ms) where it holds. True when
        ``until`` held (False without one).

        Between two parts' work the lower computer and the driver core run as one
        :meth:`SimLoop.advance` (batched where that changes nothing: driver_base's face only
        publishes, at each frame's own time); /clock gets every 10 ms it passed."""
        every = max(1, round(0.05 / self.dt))
        end = self.steps + periods
        while self.steps < end:
            with self.lock:
                self.board.drain()
                self._set_ros_time()
                self._publish_clock()
                step = self.steps
                for job in self.jobs:
                    job.run_if_due(step)
                upto = min(end, min(job.due for job in self.jobs),
                           (step // every + 1) * every if until is not None else end)
                self._advance(max(1, upto - step))
                self.steps = max(upto, step + 1)
                mcu = self.loop.mcu
                for hook in self._hooks:
                    hook(mcu)
            if until is not None and self.steps % every == 0 and until():
                break
        with self.lock:  # ROS time is where the loop stands (a paused robot's goals)
            self._set_ros_time()
            self._publish_clock()
        return until is not None and bool(until())

    def _advance(self, periods: int) -> None:
        """:meth:`SimLoop.advance` of ``periods`` with the contact gate (as
        :meth:`WorldSim.run_periods`): all of them as one batch without the surroundings when
        the free space measured covers them (:meth:`ContactGate.clear_run`), else one period
        after the gate's check (which measures the free space when due) and the rest again."""
        gate, loop = self.gate, self.loop
        while periods > 0:
            if periods > 1 and gate.clear_run(periods):
                loop.advance(periods)
                return
            gate.check()
            loop.advance(1)
            periods -= 1

    # -- what a step can wait for (simcontrol's ``until``) --------------------------------------
    def navigation_idle(self) -> bool:
        nav = self.navigation
        if nav is None:
            return True
        with self.lock:
            return not nav.navigator_active() and not nav.steps.active

    def task_idle(self) -> bool:
        tasks = self.tasks
        if tasks is None:
            return True
        with self.lock:
            return not tasks.machine.active

    def condition(self, name: str) -> Callable[[], bool] | None:
        """The ``until`` of a step by name (:data:`UNTIL`); ValueError when unknown."""
        if name not in UNTIL:
            raise ValueError(f"until {name!r} is not known; one of: "
                             + ", ".join(repr(u) for u in UNTIL))
        return {"": None, "move_base": self.navigation_idle,
                "task": self.task_idle}[name]

    def shutdown(self) -> dict[str, int]:
        """Stop every face (the top ones first); the counts of all of them."""
        stats: dict[str, int] = {}
        for face in (self.tasks, self.navigation, self.world, self.driver):
            if face is None:
                continue
            if face is self.driver:
                face.stop.set()
                with self.lock:
                    for sub in face._subs:
                        sub.unregister()
                    for service in face._services:
                        service.shutdown()
            else:
                face.shutdown()
            stats.update({k: int(v) for k, v in getattr(face, "stats", {}).items()})
        stats.update(self.loop.driver.stats)
        if self.truth_log is not None:
            self.truth_log.close()
        return stats
