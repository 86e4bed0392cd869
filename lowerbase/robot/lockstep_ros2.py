"""``lowerbase robot --ros2 --sim-time``: the lockstep robot (:class:`~lowerbase.robot.lockstep.
LockstepRobot`, unchanged) with its interface on ROS 2; with ``--robot legged``, the legged one
(:class:`~lowerbase.robot.lockstep_legged.LeggedLockstep`, unchanged).

Every part runs in this process on one simulated clock, as on ROS 1; the faces are the ROS 1
ones, on :class:`Ros2Side`: one rclpy node ``/lowerbase_robot`` carries every face's
topics, services and actions under the names they have on ROS 1
(:class:`lowerbase.ros2.local.Ros2LocalWire`), a :class:`~lowerbase.ros2.wire.RclpyShim` stands
in for rospy (ROS time is the simulated time), the message builders get
``builtin_interfaces/Time`` stamps (:class:`~lowerbase.ros2.compat.AnyStampIo`), and the ROS 1
names of the ROS 2 types are added once (:func:`lowerbase.ros2.compat.ros1_names`).
/clock (rosgraph_msgs/Clock) is published every 10 ms of simulated time; the node's
``use_sim_time`` is true. nav2's ``navigate_to_pose`` and ``compute_path_to_pose`` are served
beside the vendor's move_base (:mod:`lowerbase.navigation.nav2`). The legged robot's face
(:class:`~lowerbase.legged_driver.node.LeggedNode`) gets its ROS 2 types from
:func:`lowerbase.ros2.compat.legged_ros`.

An rclpy executor (several threads: an action goal's execute callback follows its goal until
it ends) serves the subscriptions, services and actions; the lockstep loop runs in the main
thread (:class:`~lowerbase.robot.simcontrol.SimControl`, as on ROS 1: paced by ``--speed``, or
paused and moved by ``/lowerbase/step``, with ``/lowerbase/pause`` and the latched
``/lowerbase/sim_status``) until SIGINT/SIGTERM or ``duration`` wall seconds.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from lowerbase.robot.lockstep import NODE, LockstepOptions, LockstepRobot

log = logging.getLogger(__name__)

EXECUTOR_THREADS = 8  #: the action goals followed at once, plus services and subscriptions


class Ros2Side:
    """How the lockstep robot reaches ROS 2 (the twin of :class:`~lowerbase.robot.lockstep.
    Ros1Side`) on one rclpy ``node``."""

    def __init__(self, node: Any) -> None:
        from lowerbase.ros2.compat import ros1_names
        from lowerbase.ros2.wire import RclpyShim, Ros2Wire

        ros1_names()
        self.node = node
        self.shim = RclpyShim(node, params={"/use_sim_time": True})
        self.now = 0.0  #: [s] simulated time (ROS time here)
        self.shim.Time.source = lambda: self.now
        self.real = Ros2Wire(node)

    def board(self) -> Any:
        from lowerbase.ros2.local import Ros2Switchboard

        return Ros2Switchboard(self.shim, self.node)

    def wire(self, board: Any, name: str) -> Any:
        from lowerbase.ros2.local import Ros2LocalWire

        return Ros2LocalWire(self.shim, board, name, self.real)

    def param(self, name: str, default: Any = None) -> Any:
        """A global ROS 1 name as a ROS 2 parameter of this node (``/move_base/recovery_
        behaviors`` is ``move_base.recovery_behaviors``), declared here so that ``ros2 param``
        lists it: its value from the command line (``_move_base/recovery_behaviors:=[...]``),
        else ``default``. ``/use_sim_time`` is the shim's."""
        if name == "/use_sim_time":
            return self.shim.get_param(name, default)
        from rcl_interfaces.msg import ParameterDescriptor

        key = name.strip("/").replace("/", ".")
        if not self.node.has_parameter(key):
            self.node.declare_parameter(key, None, ParameterDescriptor(dynamic_typing=True))
        value = self.node.get_parameter(key).value
        if value is None:
            return default
        return list(value) if isinstance(value, (list, tuple)) or hasattr(value, "tolist") \
            else value

    def face_ros(self, face: str) -> Any:
        from lowerbase.ros2.compat import AnyStampIo
        from lowerbase.ros2.wire import StampedIo

        if face == "tasks":
            return self.shim
        if face == "legged":
            from lowerbase.ros2.compat import legged_ros

            return legged_ros(self.shim)
        if face == "driver":
            from lowerbase.driver import ros_io

            return self.shim, StampedIo(ros_io)
        if face == "world":
            from lowerbase.world import ros_msgs as world_io

            return self.shim, AnyStampIo(world_io)
        from lowerbase.navigation import ros_msgs as nav_io

        return self.shim, AnyStampIo(nav_io)

    def set_time(self, now: float) -> None:
        self.now = now

    def clock_publisher(self) -> Any:
        from rosgraph_msgs.msg import Clock

        from lowerbase.ros2.wire import clock_qos

        return self.node.create_publisher(Clock, "/clock", clock_qos())

    def clock_sender(self, publisher: Any) -> Callable[[float], None] | None:
        from rosgraph_msgs.msg import Clock

        from lowerbase.ros2.wire import Stamp

        if publisher.get_subscription_count() == 0:
            return None
        return lambda t: publisher.publish(Clock(clock=Stamp.from_sec(t).to_msg()))


def run(opts: LockstepOptions, speed: float | None, ros_args: Sequence[str] = (),
        duration: float | None = None,
        make: Callable[[LockstepOptions, Any, Ros2Side], Any] = LockstepRobot,
        paused: bool = False) -> int:
    """Build the robot on ROS 2, run it until a signal or ``duration`` [s of wall time];
    ``paused``: time moves only on /lowerbase/step. ``make(opts, rospy, side)``: the robot
    (:class:`LockstepRobot`, or :class:`~lowerbase.robot.lockstep_legged.LeggedLockstep`)."""
    from lowerbase.driver.ros2_node import import_rclpy, start_node
    from lowerbase.robot.pace import Pacer
    from lowerbase.robot.simcontrol import SimControl

    rclpy = import_rclpy()
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.parameter import Parameter

    context, node = start_node(NODE, ros_args, parameter_overrides=[
        Parameter("use_sim_time", Parameter.Type.BOOL, True)],
        automatically_declare_parameters_from_overrides=True)
    side = Ros2Side(node)
    stop = threading.Event()
    executor = MultiThreadedExecutor(num_threads=EXECUTOR_THREADS, context=context)
    robot: Any = None
    nav2: Any = None
    control: SimControl | None = None

    def serve() -> None:
        while not stop.is_set() and rclpy.ok(context=context):
            try:
                executor.spin_once(timeout_sec=0.1)
            except Exception:  # a callback's error: logged (with its traceback), served on
                log.exception("an rclpy callback failed")

    spinner = threading.Thread(target=serve, name="lowerbase_robot-rclpy", daemon=True)
    def on_signal(*_: Any) -> None:
        stop.set()
        if control is not None:
            control.stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        robot = make(opts, side.shim, side)
        robot.advertise()
        navigation = getattr(robot, "navigation", None)  # the legged robot has none
        if navigation is not None:
            from lowerbase.navigation.nav2 import Nav2Servers

            nav2 = Nav2Servers(navigation)
            nav2.start()
        control = SimControl(robot, Pacer(speed), paused=paused)
        control.advertise(side.real)
        executor.add_node(node)
        spinner.start()
        parts = getattr(robot, "parts", None)  # the legged robot's; the wheeled one's map
        what = ", ".join(parts) if parts else f"map {opts.map}"
        moved = "paused: /lowerbase/step moves it" if paused else \
            f"at {'max' if speed is None else f'{speed:g} x'}"
        print(f"lowerbase robot: {node.get_fully_qualified_name()} on ROS 2 (domain "
              f"{context.get_domain_id()}), {what}, simulated time {moved}; Ctrl-C stops",
              flush=True)
        deadline = None if duration is None else time.monotonic() + duration

        def tick() -> None:
            if stop.is_set() or (deadline is not None and time.monotonic() >= deadline):
                control.stop.set()

        if not stop.is_set():
            control.run(tick)
    finally:
        stop.set()
        if control is not None:
            control.shutdown()
        side.shim.signal_shutdown("robot stopped")
        for s, h in previous.items():
            signal.signal(s, h)
        if spinner.is_alive():  # out of rclpy's wait before the faces' entities go
            spinner.join(timeout=3.0)
        if nav2 is not None:
            nav2.shutdown()
        if robot is not None:
            stats = robot.shutdown()
            stats.update(robot.board.stats)
            if control is not None:
                stats.update(control.stats)
                stats["slowed"] = control.pacer.behind
            counts = ", ".join(f"{k} {v}" for k, v in sorted(stats.items()) if v)
            print(f"lowerbase robot: stopped at {robot.now:.2f} s of simulated time; "
                  f"{counts or 'nothing counted'}", file=sys.stderr, flush=True)
        # rclpy 9.1's Executor.shutdown destroys its guard condition without waiting for the
        # callbacks still in its threads, which then fail on it ("The following exception was
        # never retrieved: ... destruction was requested"): they end first
        pool = getattr(executor, "_executor", None)
        if pool is not None:
            pool.shutdown(wait=True)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return 0
