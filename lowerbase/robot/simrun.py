"""``lowerbase robot --sim-time``: the lockstep robot on a ROS master, from start to stop.

On the master (started by the caller when none answers), with ``/use_sim_time`` true: this
process becomes the node ``/lowerbase_robot``, which carries every part's face
(:class:`~lowerbase.robot.lockstep.LockstepRobot`) and publishes /clock; a recorder child
(``--mcap``/``--foxglove``) subscribes to its topics like any outside node. The loop runs in
this thread (:class:`~lowerbase.robot.simcontrol.SimControl`) until Ctrl-C, SIGTERM, SIGHUP or
``duration`` wall seconds.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from lowerbase.robot.holdwatch import HoldWatch
from lowerbase.robot.lockstep import NODE, LockstepOptions, LockstepRobot
from lowerbase.robot.pace import Pacer
from lowerbase.robot.simcontrol import SimControl
from lowerbase.ros1 import held
from lowerbase.ros1.wire import RosWire, publish_synchronously

#: [bytes] unsent to one subscriber that make it a holder (its socket buffers hold ~2.5 MB on
#: loopback; one that reads has next to none)
HELD_BYTES = 64 * 1024


@dataclass(frozen=True)
class SimRun:
    """How the lockstep robot runs: ``speed`` None is ``max``; ``paused`` starts it paused;
    ``duration`` [s of wall time] ends it (None: Ctrl-C)."""

    options: LockstepOptions
    speed: float | None = 1.0
    paused: bool = False
    duration: float | None = None
    legged: bool = False  #: the legged robot (lowerbase.robot.lockstep_legged)


def init_rospy() -> Any:
    """rospy as the node /lowerbase_robot of this process, on loopback with a local master,
    following no /clock (its own time is set directly: lowerbase.robot.lockstep)."""
    import rosgraph

    from lowerbase.ros1.loopback import loopback_address
    from lowerbase.ros1.node import ToRosout, import_rospy

    rospy = import_rospy()
    address = loopback_address(os.environ, rosgraph.get_master_uri())
    if address is not None:
        os.environ["ROS_IP"] = address
    logging.getLogger("rospy").setLevel(logging.WARNING)
    rospy.init_node(NODE, disable_signals=True)
    import rospy.impl.simtime as simtime

    own = getattr(simtime, "_clock_sub", None)
    if own is not None:  # it would set this process' time back to its own older /clock
        own.unregister()
    logger = logging.getLogger("lowerbase")
    logger.addHandler(ToRosout())
    logger.propagate = False
    return rospy


def speed_text(speed: float | None) -> str:
    return "max" if speed is None else f"{speed:g}"


def status_text(control: SimControl) -> str:
    robot, pacer = control.robot, control.pacer
    factor = pacer.factor()
    state = "paused" if control.paused else f"--speed {speed_text(pacer.speed)}"
    achieved = "" if factor is None or control.paused else f", {factor:.1f} x real time"
    behind = f", slowed {pacer.behind} x" if pacer.behind else ""
    return f"sim {robot.now:.1f} s ({state}{achieved}{behind})"


def run_sim(run: SimRun, show: Callable[[str], None],
            alive: Callable[[], str | None] = lambda: None) -> dict[str, int]:
    """Build, advertise and run until stopped; ``show`` gets the status text between chunks,
    ``alive`` names a helper process that ended (the run then stops). The counts of the
    parts at the end."""
    rospy = init_rospy()
    robot: Any
    if run.legged:
        from lowerbase.robot.lockstep_legged import LeggedLockstep

        robot = LeggedLockstep(run.options, rospy)
        parts = robot.parts
    else:
        robot = LockstepRobot(run.options, rospy)
        parts = ("driver_base", "world", *run.options.parts)
    control = SimControl(robot, Pacer(run.speed), paused=run.paused)
    previous = {s: signal.signal(s, lambda *_: control.stop.set())
                for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    ended: list[str] = []
    watch: HoldWatch | None = None
    try:
        robot.advertise()
        control.advertise(RosWire(rospy))
        publish_synchronously(rospy)  # a busy host slows time down; nothing is dropped
        # ... and a subscriber that reads no more holds it: said, with who it is
        watch = HoldWatch(lambda: robot.now, control.should_run,
                          lambda: held.backlogs(rospy, HELD_BYTES))
        watch.start()
        deadline = None if run.duration is None else time.monotonic() + run.duration
        import rosgraph

        paused = ", paused: /lowerbase/step moves it" if run.paused else ""
        print(f"lowerbase robot: ready on ROS master {rosgraph.get_master_uri()}, in lockstep on "
              f"simulated time (/use_sim_time true, /clock from it, --speed "
              f"{speed_text(run.speed)}{paused}); parts: {', '.join(parts)}; Ctrl-C stops",
              flush=True)

        def tick() -> None:
            show(status_text(control))
            gone = alive()
            if gone:
                ended.append(gone)
                control.stop.set()
            if deadline is not None and time.monotonic() >= deadline:
                control.stop.set()

        control.run(tick)
    finally:
        control.shutdown()
        stats = robot.shutdown()
        stats.update(control.stats)
        if watch is not None:
            watch.close()
            stats.update(watch.stats)
        stats["slowed"] = control.pacer.behind
        print(f"lowerbase robot: {status_text(control)}", flush=True)
        with contextlib.suppress(Exception):
            rospy.signal_shutdown("lowerbase robot stopped")
        for s, handler in previous.items():
            signal.signal(s, handler)
    if ended:
        from lowerbase.robot.supervisor import RobotError

        raise RobotError(f"{ended[0]} ended; the robot stopped")
    return stats
