"""``lowerbase robot --robot legged --sim-time``: the legged robot in lockstep on one simulated
clock: :class:`LeggedLockstep`.

The legged lower computer (the body controller, 12 MIT actuators on 4 leg buses, the pack) and
the legged driver core exchange every frame at once, every 1 ms of simulated time
(:class:`~lowerbase.simloop.legged.LeggedSimLoop`); the legged driver's ROS face
(:class:`~lowerbase.legged_driver.node.LeggedNode`: robot_state, /cmd_vel, the planning services,
set_map, set_listen, ``~walk``/``~stand``/``~sit``) ticks at its command rate and publishes
robot_state at its ``publish_rate`` of simulated time, as the node does on the wall clock.
ROS time is the simulated time, /clock every 10 ms of it. The interface to
:mod:`lowerbase.robot.simcontrol` is :class:`~lowerbase.robot.lockstep.LockstepRobot`'s, and so
is how it reaches ROS (``side``: :class:`~lowerbase.robot.lockstep.Ros1Side`, or ROS 2's
:class:`~lowerbase.robot.lockstep_ros2.Ros2Side`).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

from lowerbase.robot.lockstep import CLOCK_RATE, LockstepOptions, Ros1Side


class LeggedLockstep:
    """The legged robot and its driver's face on one simulated clock (see the module)."""

    def __init__(self, opts: LockstepOptions, rospy: Any, side: Any = None) -> None:
        from lowerbase.legged_driver.node import (
            NODE_NAME,
            LeggedNode,
            load_legged_settings,
            make_map_dir,
        )
        from lowerbase.simloop.legged import LeggedSimLoop

        self.opts = opts
        self.rospy = rospy
        self.side = side if side is not None else Ros1Side(rospy)
        self.lock = threading.RLock()
        settings, config = load_legged_settings({})
        make_map_dir(config)  # set_map's PCD files, as `lowerbase driver --robot legged`
        kwargs: dict[str, Any] = {} if opts.soc is None else {"soc": opts.soc}
        self.loop = LeggedSimLoop(config=config, **kwargs)
        self.dt = self.loop.dt
        self.board = self.side.board()
        self.node = LeggedNode(settings, config, [], core=self.loop.driver,
                               wire=self.side.wire(self.board, NODE_NAME), lock=self.lock,
                               ros=self.side.face_ros("legged"))
        self.steps = 0
        self._tick_every = self.loop.tick_every
        self._publish_every = max(1, round(1.0 / (settings.publish_rate * self.dt)))
        self._clock_every = max(1, round(1.0 / (CLOCK_RATE * self.dt)))
        self._clock_pub: Any = None
        self.parts = ("legged lower computer", "legged driver")

    @property
    def now(self) -> float:
        return float(self.loop.now)

    def advertise(self) -> None:
        self._set_ros_time()
        self._clock_pub = self.side.clock_publisher()
        with self.lock:
            self.node.advertise()

    def _set_ros_time(self) -> None:
        self.side.set_time(float(self.loop.now))

    def run_periods(self, periods: int, until: Callable[[], bool] | None = None) -> bool:
        """``periods`` 1 ms periods: /clock every 10 ms, the driver's tick and goal at its
        command rate, robot_state at its publish rate, then the lower computer's step."""
        loop, node = self.loop, self.node
        for _ in range(periods):
            with self.lock:
                step = self.steps
                if step % self._clock_every == 0:
                    self.board.drain()
                    self._set_ros_time()
                    send = self.side.clock_sender(self._clock_pub)
                    if send is not None:  # None: nobody on ROS listens, nothing is built
                        send(float(loop.now))
                if step % self._tick_every == 0:
                    node.pursue_goal()
                    node.core.tick()
                if step % self._publish_every == 0:
                    self._set_ros_time()
                    node.publish_state()
                loop.lower.step()
                loop.steps += 1
                loop.clock.advance(loop.dt)
                self.steps += 1
            if until is not None and self.steps % self._tick_every == 0 and until():
                break
        with self.lock:
            self._set_ros_time()
        return until is not None and bool(until())

    def condition(self, name: str) -> Callable[[], bool] | None:
        if name == "":
            return None
        if name == "walked":  # the waypoint mission is over (or none was given)
            return self._mission_done
        raise ValueError(f"until {name!r} is not known for the legged robot; one of: '', "
                         "'walked'")

    def _mission_done(self) -> bool:
        with self.lock:
            return not self.node.core.follower.active

    def shutdown(self) -> dict[str, int]:
        stats: dict[str, int] = {}
        self.node.stop.set()
        with self.lock:
            for handle in [*self.node._handles, self.node._joy_sub]:
                if handle is not None:
                    (handle.unregister if hasattr(handle, "unregister") else handle.shutdown)()
        stats.update({k: int(v) for k, v in self.node.core.stats.items()
                      if isinstance(v, (int, float)) and math.isfinite(v)})
        self.loop.close()
        return stats
