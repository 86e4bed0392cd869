"""The navigation node's control loop on its clock: :func:`control_loop` runs one control tick
per period of wall time, or of ROS time under /use_sim_time (``lowerbase.world.pacing``: woken
by each /clock), and hands the tick that clock's time, so every deadline of the Navigator and
the StepController (stuck, settle, waiting, blocked patience) is on it too. ROS-free."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any, Protocol

from lowerbase.world.pacing import Pace, RateWatch, RosPace, paced_loop

log = logging.getLogger(__name__)

Pose = tuple[float, float, float]


class Rates(Protocol):
    """The rates :func:`control_loop` keeps (the node's ``NavigationSetup``)."""

    @property
    def rate_hz(self) -> float: ...  # [Hz] control ticks

    @property
    def costmap_rate_hz(self) -> float: ...  # [Hz] the local costmap's publishing


def pose2d(transform: Any) -> Pose | None:
    """(x, y, yaw) of a geometry_msgs/Transform; None if not finite."""
    tr, q = transform.translation, transform.rotation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    if not all(math.isfinite(v) for v in (tr.x, tr.y, yaw)):
        return None
    return (float(tr.x), float(tr.y), yaw)


def control_loop(pace: Pace, tick: Callable[[float], None],
                 publish_costmaps: Callable[[bool], None], setup: Rates,
                 running: Callable[[], bool], watch: RateWatch | None = None) -> None:
    """``tick(now)`` every ``1 / setup.rate_hz`` s of ``pace``'s clock (``now`` on that clock),
    the costmaps every ``setup.costmap_rate_hz``. On ROS time a late tick is caught up within
    1 s (a longer stall starts the schedule again: lowerbase.world.pacing.paced_loop). On wall
    time a late tick is missed, as move_base's loop misses its rate: ticks back to back would
    all see the same pose and time; the missed ones are counted in ``watch`` (its
    :attr:`~lowerbase.world.pacing.RateWatch.total_dropped`), whose line on the rate kept is
    logged as a warning at most every 30 s."""
    every = max(1, round(setup.rate_hz / setup.costmap_rate_hz))
    catch_up = isinstance(pace, RosPace)
    watch = watch if watch is not None else RateWatch("control loop", setup.rate_hz, what="tick")
    k = 0

    def work() -> None:
        nonlocal k
        now = pace.now()
        tick(now)
        if k % every == 0:
            publish_costmaps(True)
        k += 1
        if not catch_up:
            watch.done_and_warn(now, log)

    paced_loop(pace, work, setup.rate_hz, catch_up, running, watch.dropped)
