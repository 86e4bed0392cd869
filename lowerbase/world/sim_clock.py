"""``lowerbase world --publish-clock``: the world as the simulator publishes /clock (as Gazebo
and Stage do), from the emulator's ground truth, for nodes running with ``/use_sim_time``.

:class:`TruthTime` maps each truth sample's ``t`` (the emulator's time since its first boot,
K x real time on ``emulate --speed K``) to the published time, which never goes backwards: an
emulator restarted under the same world starts its ``t`` again near 0, and /clock then goes on
from where it was (the new run's time plus an offset, counted in ``restarts``).

:class:`ClockedTruth` wraps a :class:`~lowerbase.world.truth_stream.TruthReceiver`: a thread of
its own reads the stream as it comes and publishes one /clock per sample (50 Hz of emulator
time), so /clock does not wait for the sensor loops; the world reads the samples through it
(one lock around the receiver, which two threads now drain).
"""

from __future__ import annotations

import select
import threading
from collections import Counter
from collections.abc import Callable
from typing import Any

from lowerbase.world.truth_stream import TruthReceiver, TruthSample


class TruthTime:
    """The /clock time of each sample: ``t + offset``, never decreasing."""

    def __init__(self) -> None:
        self.offset = 0.0
        self.last_t: float | None = None
        self.last_clock = 0.0
        self.stats: Counter[str] = Counter()

    def clock(self, sample: TruthSample) -> float:
        t = sample.t
        if self.last_t is not None and t < self.last_t:  # a new emulator: go on from here
            self.offset = self.last_clock - t
            self.stats["restarts"] += 1
        self.last_t = t
        self.last_clock = max(self.last_clock, t + self.offset)
        return self.last_clock


class ClockedTruth:
    """A :class:`~lowerbase.world.truth.TruthSource` that also publishes /clock per sample."""

    def __init__(self, receiver: TruthReceiver) -> None:
        self.receiver = receiver
        self.time = TruthTime()
        self.published = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._publish: Callable[[float], None] | None = None
        self._thread: threading.Thread | None = None
        self._inner = receiver.on_sample
        receiver.on_sample = self._on_sample

    # -- TruthSource, for the world's loops ------------------------------------------------------
    def sample(self) -> TruthSample | None:
        with self._lock:
            return self.receiver.sample()

    def pose(self) -> tuple[float, float, float] | None:
        with self._lock:
            return self.receiver.pose()

    def age(self) -> float:
        with self._lock:
            return self.receiver.age()

    @property
    def latest(self) -> TruthSample | None:
        return self.receiver.latest

    # -- /clock ----------------------------------------------------------------------------------
    def _on_sample(self, sample: TruthSample) -> None:  # under self._lock (every drain is)
        clock = self.time.clock(sample)
        if self._publish is not None:
            self._publish(clock)
            self.published += 1
        if self._inner is not None:
            self._inner(sample)

    def start(self, publish: Callable[[float], None]) -> None:
        """Publish every sample from now on with ``publish(seconds)``, from a thread."""
        self._publish = publish
        self._thread = threading.Thread(target=self._run, name="world-clock", daemon=True)
        self._thread.start()

    def start_ros(self, rospy: Any) -> None:
        """:meth:`start` with a rospy publisher of rosgraph_msgs/Clock on /clock."""
        import importlib

        Clock = importlib.import_module("rosgraph_msgs.msg").Clock
        pub = rospy.Publisher("/clock", Clock, queue_size=10)
        self.start(lambda seconds: pub.publish(Clock(clock=rospy.Time.from_sec(seconds))))

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                select.select([self.receiver], [], [], 0.2)
            except (OSError, ValueError):  # the receiver was closed under us
                return
            with self._lock:
                self.receiver.drain()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self.receiver.on_sample = self._inner
