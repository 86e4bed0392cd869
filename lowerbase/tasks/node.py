"""Tasks as a ROS1 node (``lowerbase tasks``): the seed's exec_task and robot_status.

A thin rospy layer over :class:`~lowerbase.tasks.machine.TaskMachine`:

- serves ``exec_task`` (woosh_msgs/ExecTask) and publishes ``robot_status``
  (woosh_msgs/RobotStatus, latched, only on change), the names of shared/seeds/000;
- drives navigation as an actionlib client of /move_base (woosh_msgs/MoveBaseAction) and of
  /cmd_vel_control (woosh_msgs/StepControlAction, the docking moves), both served by
  ``lowerbase navigation`` (:mod:`lowerbase.tasks.ros_clients`); it never commands a twist;
- reads the chassis from driver_base's topics and the world's localization
  (:mod:`lowerbase.tasks.inputs`).

The machine ticks at ``rate_hz`` on rospy's clock (rospy.Rate, rospy.get_time), so it runs on
/clock under use_sim_time. Threads: the main loop, rospy's subscriber and service threads share
one lock. A malformed message is a counted, logged drop; a bad request a failed response.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any

from lowerbase.errors import LowerbaseError, WorldError, count_drop
from lowerbase.tasks.inputs import (
    PART_DOWN_PARAM,
    PART_NOTE_MAX,
    PART_REPORTED_PARAM,
    ChassisInputs,
    finite_pose,
)
from lowerbase.tasks.model import Pose, Status, TaskRequest, TaskResponse
from lowerbase.tasks.plan import TaskConfig
from lowerbase.text import clip
from lowerbase.world.places import Places

log = logging.getLogger(__name__)

NODE_NAME = "tasks"


@dataclass
class TasksSetup:
    """Everything the node needs, checked without ROS (see ``lowerbase.cli.tasks``)."""

    places: Places
    config: TaskConfig = field(default_factory=TaskConfig)
    map_frame: str = "map"
    pose_timeout: float = 1.0  #: [s] without movebase_pose2d: localization lost

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pose_timeout) and self.pose_timeout > 0):
            raise LowerbaseError(f"pose_timeout = {self.pose_timeout!r}: expected seconds > 0")


def import_ros() -> Any:
    """rospy; RosUnavailableError in one line if ROS (or actionlib) is missing."""
    from lowerbase.errors import RosUnavailableError
    from lowerbase.ros1.node import ROS_HINT

    try:
        import actionlib  # type: ignore[import-untyped]  # noqa: F401
        import rospy
        from woosh_msgs.srv import ExecTask  # noqa: F401
    except ImportError as exc:
        raise RosUnavailableError(f"ROS is not installed ({exc}): {ROS_HINT}") from None
    return rospy


@cache
def _odom_conversion() -> tuple[str, Callable[[Any], tuple[float, float, float]]]:
    """/odom's conversion key and function (imported once: /odom comes at 50 Hz)."""
    from lowerbase.world.ros_msgs import ODOM_POSE, odom_pose

    return ODOM_POSE, odom_pose


def request_of(msg: Any, frame: str = "map") -> TaskRequest:
    """An ExecTask request as the machine's TaskRequest; WorldError on a pose in another
    frame or with a bad orientation (a non-finite position is the machine's refusal)."""
    from lowerbase.world.ros_msgs import yaw_of

    poses: list[Pose] = []
    for i, p in enumerate(msg.poses, 1):
        got = p.header.frame_id.lstrip("/")
        if got not in ("", frame):
            raise WorldError(f"pose {i} is in frame {clip(got)}: send poses in {frame!r}")
        yaw = yaw_of(p.pose.orientation, f"pose {i}")
        poses.append((float(p.pose.position.x), float(p.pose.position.y), yaw))
    custom = msg.custom
    return TaskRequest(int(msg.task_exect), int(msg.task_id), int(msg.task_type),
                       int(msg.direction), int(msg.task_type_no), str(msg.mark_no),
                       tuple(poses), custom[0] if isinstance(custom, bytes) and custom
                       else int(custom or 0))


class TasksNode:
    """The exec_task service, the robot_status publisher, the chassis subscribers and the loop
    around one TaskMachine."""

    def __init__(self, setup: TasksSetup, *, wire: Any = None, lock: Any = None,
                 nav: Any = None, steps: Any = None, rospy: Any = None) -> None:
        """``wire``: how the face reaches ROS (:mod:`lowerbase.ros1.wire`; None: rospy as is);
        ``lock``: shared with the other faces of this process; ``nav`` and ``steps``: the
        machine's Navigation and step moves (None: actionlib clients of /move_base and
        /cmd_vel_control; in one process with navigation: :mod:`lowerbase.tasks.local_nav`);
        ``rospy``: a stand-in for rospy (ROS 2: :mod:`lowerbase.robot.lockstep_ros2`)."""
        from lowerbase.ros1.wire import RosWire
        from lowerbase.tasks.machine import TaskMachine

        self.rospy = rospy if rospy is not None else import_ros()
        from woosh_msgs.msg import RobotStatus

        self.wire = wire if wire is not None else RosWire(self.rospy)
        self.setup = setup
        self.lock = lock if lock is not None else threading.RLock()
        self.inputs = ChassisInputs(pose_timeout=setup.pose_timeout)
        self.stats: dict[str, int] = {"requests": 0, "refused": 0, "published": 0,
                                      "bad_request": 0, "bad_pose": 0, "bad_odom": 0}
        self._status_pub = self.wire.publisher("robot_status", RobotStatus, queue_size=20,
                                               latch=True)
        if nav is None or steps is None:
            from lowerbase.tasks.ros_clients import ActionNavigation, ActionSteps

            nav = ActionNavigation("move_base", setup.map_frame)
            steps = ActionSteps("cmd_vel_control")
        self.nav, self.steps = nav, steps
        self.machine = TaskMachine(self.nav, setup.places, setup.config,
                                   on_status=self._publish, steps=self.steps)
        self._subs: list[Any] = []
        self._service: Any = None
        self._part_noted = self._part_reported = ""

    def advertise(self) -> None:
        from geometry_msgs.msg import Pose2D
        from nav_msgs.msg import Odometry
        from std_msgs.msg import String, UInt64
        from woosh_msgs.msg import BMS, Battery
        from woosh_msgs.srv import ExecTask

        sub = self.wire.subscriber
        self._subs = [
            sub("driver_base/link_state", String, self._on_link, queue_size=5),
            sub("status_code", UInt64, self._on_code, queue_size=5),
            sub("/battery", Battery, self._on_battery, queue_size=2),
            sub("driver_base/bms", BMS, self._on_bms, queue_size=2),
            sub("/odom", Odometry, self._on_odom, queue_size=5),
            sub("movebase_pose2d", Pose2D, self._on_pose, queue_size=5),
            sub("lowerbase/localization", String, self._on_localization, queue_size=2),
        ]
        self._service = self.wire.service("exec_task", ExecTask, self._exec_task)

    # -- ROS -> machine ------------------------------------------------------------------------
    def _count_bad(self, key: str, what: str) -> None:
        count_drop(self.stats, key, log, what)

    def _on_link(self, msg: Any) -> None:
        with self.lock:
            self.inputs.link_state = str(msg.data)

    def _on_code(self, msg: Any) -> None:
        with self.lock:
            self.inputs.status_code = int(msg.data)

    def _on_battery(self, msg: Any) -> None:
        with self.lock:
            self.inputs.soc = float(msg.batteryPercentage)

    def _on_bms(self, msg: Any) -> None:
        with self.lock:
            self.inputs.bms_status = int(msg.BMSStatus)

    def _on_odom(self, msg: Any) -> None:
        try:
            pose = self.wire.convert(msg, *_odom_conversion())
        except WorldError as exc:
            self._count_bad("bad_odom", str(exc))
            return
        with self.lock:
            self.inputs.odom = pose

    def _on_localization(self, msg: Any) -> None:
        with self.lock:
            self.inputs.localization = str(msg.data)[:200]

    def _on_pose(self, msg: Any) -> None:
        pose = finite_pose(msg.x, msg.y, msg.theta)
        if pose is None:
            self._count_bad("bad_pose", f"movebase_pose2d: not finite ({msg.x}, {msg.y}, "
                            f"{msg.theta})")
            return
        with self.lock:
            self.inputs.pose, self.inputs.pose_time = pose, self.rospy.get_time()

    def _exec_task(self, msg: Any) -> Any:
        from woosh_msgs.srv import ExecTaskResponse

        self.stats["requests"] += 1
        with self.lock:
            try:
                req = request_of(msg, self.setup.map_frame)
            except WorldError as exc:
                self.stats["bad_request"] += 1
                res = TaskResponse(False, str(exc), int(self.machine.robot_state()))
            else:
                res = self.machine.request(req, self.rospy.get_time())
        if not res.success:
            self.stats["refused"] += 1
        log.info("exec_task %s: %s", "accepted" if res.success else "refused", res.message)
        return ExecTaskResponse(success=res.success, message=res.message,
                                statusCode=res.status_code)

    # -- machine -> ROS ------------------------------------------------------------------------
    def _publish(self, status: Status) -> None:
        from woosh_msgs.msg import RobotStatus

        self._status_pub.publish(RobotStatus(**status.fields()))
        self.stats["published"] += 1

    def tick(self) -> None:
        now = self.rospy.get_time()
        with self.lock:
            self.machine.tick(now, self.inputs.chassis(now))

    def read_part_down(self) -> None:
        """The supervisor's /lowerbase/part_down (cached by rospy, updated by the master) into
        the chassis inputs; logged (and so on /rosout) when it changes."""
        value = self.rospy.get_param_cached(PART_DOWN_PARAM, "")
        note = value[:PART_NOTE_MAX] if isinstance(value, str) else ""  # unset: {}
        with self.lock:
            self.inputs.part_down = note
        if note != self._part_noted:
            self._part_noted = note
            if note:
                log.error("%s: robot_status shows the robot ABNORMAL", note)

    def acknowledge_part_down(self) -> None:
        """Once robot_status carries the part that ended, /lowerbase/part_reported says so
        (the supervisor waits for it before it stops the robot)."""
        with self.lock:
            note, shown = self.inputs.part_down, self.machine.tracker.current
        if note and note != self._part_reported and shown is not None and note in shown.msg:
            self._part_reported = note
            self.rospy.set_param(PART_REPORTED_PARAM, note)

    def spin(self) -> None:
        rospy = self.rospy
        rate = rospy.Rate(1.0 / self.setup.config.period)
        while not rospy.is_shutdown():
            self.read_part_down()
            self.tick()
            self.acknowledge_part_down()
            try:
                rate.sleep()
            except rospy.ROSInterruptException:
                break
            except rospy.ROSTimeMovedBackwardsException:  # /clock restarted
                continue

    def shutdown(self) -> None:
        with self.lock:
            if self.machine.active:
                self.nav.cancel(self.rospy.get_time())
        for sub in self._subs:
            sub.unregister()
        if self._service is not None:
            self._service.shutdown()


def run(setup: TasksSetup, ros_args: Sequence[str], where: str) -> int:
    """Start rospy on the master in ROS_MASTER_URI, build the node and spin."""
    from lowerbase.ros1.node import ros_session

    import_ros()  # one line if ROS or the message modules are missing
    with ros_session("tasks", NODE_NAME, ros_args) as session:
        node = TasksNode(setup)
        try:
            node.advertise()
            session.announce(f"{where}; exec_task and robot_status up; navigation through "
                             "/move_base and /cmd_vel_control")
            node.spin()
        finally:
            node.shutdown()
            session.stopped(node.stats)
    return 0
