"""Running the lockstep robot (:mod:`lowerbase.robot.lockstep`): :class:`SimControl`.

Free-running, simulated time goes on by 50 ms chunks as fast as ``--speed K`` allows
(:mod:`lowerbase.robot.pace`; ``max``: as fast as the host can). Paused (``--paused``, or the
service ``/lowerbase/pause`` with true), it moves only when a client calls
``/lowerbase/step`` (lowerbase_sim_msgs/Step: so many simulated seconds, or until navigation or
the task is done), and the call returns when that time has run: a test of user code then sees
the same robot, message for message, on a busy host as on an idle one. ``/lowerbase/sim_status``
(lowerbase_sim_msgs/SimStatus, latched) tells the simulated time, the achieved factor and
whether it is paused, once a wall second and after every pause or step.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from lowerbase.robot.pace import Pacer

CHUNK = 0.05  #: [s] of simulated time between two looks at the pace and the requests
MAX_STEP = 86400.0  #: [s] the longest one step may ask for
STATUS_PERIOD = 1.0  #: [s] of wall time between two /lowerbase/sim_status


@dataclass
class _StepRequest:
    periods: int
    until: Callable[[], bool] | None
    done: threading.Event = field(default_factory=threading.Event)
    met: bool = False


class SimControl:
    """Free-running or paused (see the module docstring); :meth:`run` in the main thread."""

    def __init__(self, robot: Any, pacer: Pacer, paused: bool = False) -> None:
        """``robot``: a :class:`~lowerbase.robot.lockstep.LockstepRobot` or anything with its
        ``rospy``, ``now``, ``dt``, ``run_periods`` and ``condition``."""
        self.robot = robot
        self.pacer = pacer
        self.paused = paused
        self.stop = threading.Event()
        self._cond = threading.Condition()
        self._request: _StepRequest | None = None
        self._services: list[Any] = []
        self._status_pub: Any = None
        self._status_at = -math.inf
        self.stats = {"steps_served": 0, "steps_refused": 0}

    # -- ROS -----------------------------------------------------------------------------------
    def advertise(self, wire: Any) -> None:
        """The status topic and the two services on ``wire`` (:class:`lowerbase.ros1.wire.
        RosWire` on ROS 1, :class:`lowerbase.ros2.wire.Ros2Wire` on ROS 2, where the ROS 1
        names of the service types come from :func:`lowerbase.ros2.compat.ros1_names`). A step
        holds its caller until its time has run: ``blocking`` gives it its own callback group
        on ROS 2, so the faces' callbacks go on meanwhile (rospy has a thread per call)."""
        from lowerbase_sim_msgs.msg import SimStatus
        from lowerbase_sim_msgs.srv import Step
        from std_srvs.srv import SetBool  # type: ignore[import-untyped]

        self._status_pub = wire.publisher("/lowerbase/sim_status", SimStatus, queue_size=2,
                                          latch=True)
        self._services = [wire.service("/lowerbase/step", Step, self._on_step, blocking=True),
                          wire.service("/lowerbase/pause", SetBool, self._on_pause)]
        self.publish_status()

    def publish_status(self) -> None:
        from lowerbase_sim_msgs.msg import SimStatus

        if self._status_pub is None:
            return
        self._status_at = time.monotonic()
        self._status_pub.publish(SimStatus(
            sim_time=float(self.robot.now), factor=float(self.pacer.factor() or 0.0),
            speed=float(self.pacer.speed or 0.0), paused=self.paused,
            behind=int(self.pacer.behind)))

    def _on_pause(self, req: Any) -> Any:
        from std_srvs.srv import SetBoolResponse

        with self._cond:
            self.paused = bool(req.data)
            self.pacer.restart()
            self._cond.notify_all()
        self.publish_status()
        text = "paused: time moves on /lowerbase/step" if self.paused else "running"
        return SetBoolResponse(success=True, message=f"{text} at {self.robot.now:.3f} s")

    def _on_step(self, req: Any) -> Any:
        from lowerbase_sim_msgs.srv import StepResponse

        def refuse(why: str) -> Any:
            self.stats["steps_refused"] += 1
            return StepResponse(success=False, message=why, sim_time=self.robot.now,
                                until_met=False)

        seconds = float(req.seconds)
        if not (math.isfinite(seconds) and 0.0 < seconds <= MAX_STEP):
            return refuse(f"seconds must be within (0, {MAX_STEP:g}], got {seconds:g}")
        try:
            until = self.robot.condition(str(req.until))
        except ValueError as exc:
            return refuse(str(exc))
        periods = max(1, round(seconds / self.robot.dt))
        with self._cond:
            if not self.paused:
                return refuse("the robot runs freely: pause it first (/lowerbase/pause true, "
                              "or lowerbase robot --sim-time --paused)")
            if self._request is not None:
                return refuse("another step is running: call again when it has returned")
            request = self._request = _StepRequest(periods, until)
            self._cond.notify_all()
        while not request.done.wait(0.2):
            if self.stop.is_set():
                return refuse("the robot is stopping")
        self.stats["steps_served"] += 1
        self.publish_status()
        return StepResponse(success=True, message="ran" if until is None or not request.met
                            else f"until {req.until}", sim_time=self.robot.now,
                            until_met=request.met)

    def should_run(self) -> bool:
        """Whether simulated time should be moving now: free-running, or a step running."""
        return not self.paused or self._request is not None

    # -- the loop ------------------------------------------------------------------------------
    def run(self, on_tick: Callable[[], None] | None = None) -> None:
        """Until :attr:`stop` is set: free-running chunks at the pace, or the steps asked for
        while paused; ``on_tick`` between chunks (the status line, a deadline)."""
        robot, chunk = self.robot, max(1, round(CHUNK / self.robot.dt))
        while not self.stop.is_set():
            with self._cond:
                request = self._request
                if self.paused and request is None:
                    self._cond.wait(0.1)
                    request = None
            if request is not None:
                self._serve(request, chunk)
            elif not self.paused:
                self.pacer.wait(robot.now)
                robot.run_periods(chunk)
            if time.monotonic() - self._status_at >= STATUS_PERIOD:
                self.publish_status()
            if on_tick is not None:
                on_tick()
            time.sleep(0)  # let the service threads in

    def _serve(self, request: _StepRequest, chunk: int) -> None:
        left = request.periods
        self.pacer.restart()
        while left > 0 and not self.stop.is_set():
            n = min(chunk, left)
            self.pacer.wait(self.robot.now)
            if self.robot.run_periods(n, request.until):
                request.met = True
                break
            left -= n
        with self._cond:
            self._request = None
        request.done.set()

    def shutdown(self) -> None:
        self.stop.set()
        with self._cond:
            self._cond.notify_all()
        for service in self._services:
            service.shutdown()
