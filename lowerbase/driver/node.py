"""driver_base: the ROS1 node of the upper computer, a thin rospy layer over DriverCore.

Threads (one lock, held around every DriverCore call):

* the reader thread takes frames off the bus (or a replayed log) and feeds
  ``DriverCore.on_frame``; the core's listeners publish what a frame completed (/odom_raw,
  /odom and the TF on each wheel sample, /imu/data_raw, odom_twist, odometer, status_code);
* the main thread calls ``DriverCore.tick`` every 1/command_rate seconds (motion commands,
  configuration requests, link watchdog) and publishes what is better sent once per burst
  (/battery and /driver_base/bms, the latched /driver_base/parameter and /information, and
  ``~link_state``);
* rospy's subscriber threads hand /base_cmd_vel, /smooth_cmd_vel, rgbled and rgbled_shelf to
  ``set_twist`` / ``set_led``.

/odom, /odom_raw and odom -> base_link are stamped with the wheel sample's time (the EKF's), the
rest with ``rospy.Time.now()`` when the frame was handled; DriverCore's own timeouts and the
main loop run on a :class:`~lowerbase.clock.RealClock`, or on ROS time when ``/use_sim_time``
is true (:mod:`lowerbase.driver.rostime`: 20 Hz of /clock's time). A bus that fails (a USB
adapter unplugged) is closed and reopened every second, while the core reports the lost link;
nothing here raises on bad input from the wire. Run it with ``lowerbase driver`` (see
docs/driver.md) or roslaunch (``lowerbase/driver/launch/driver_base.launch``); the
package's ``python -m lowerbase driver ARGS`` is the same.
"""

from __future__ import annotations

import contextlib
import logging
import math
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

from lowerbase.clock import Clock, RealClock, WarnLimiter
from lowerbase.driver import services
from lowerbase.driver.core import DriverConfig, DriverCore, LinkState
from lowerbase.driver.links import (  # noqa: F401 (re-export)
    REPLAY_SUFFIXES,
    BusLink,
    HandlingLag,
    ReplayLink,
)
from lowerbase.driver.settings import NodeSettings
from lowerbase.errors import RosUnavailableError
from lowerbase.ros1.node import ROS_HINT
from lowerbase.ros1.wire import wanted

log = logging.getLogger(__name__)

NODE_NAME = "driver_base"
#: [s] the oldest sample stamped with its own time (/odom, /imu, /battery); older: the publish
#: time
MAX_STAMP_AGE = 5.0


def import_ros() -> tuple[ModuleType, ModuleType]:
    """(rospy, lowerbase.driver.ros_io); RosUnavailableError with one clear line if missing."""
    try:
        import rospy

        from lowerbase.driver import ros_io
    except ImportError as exc:
        name = getattr(exc, "name", "") or ""
        if name.startswith("woosh_msgs"):
            raise RosUnavailableError(
                f"woosh_msgs is not generated for {sys.executable}: run "
                f"{Path(sys.executable).name} -m lowerbase.driver.msggen") from None
        raise RosUnavailableError(f"ROS is not installed ({exc}): {ROS_HINT}") from None
    return rospy, ros_io


class Throttle:
    """Lets a topic through at most ``rate`` [Hz] on average (0: always).

    A sample is accepted from half a period before it is due, so the jitter of a source that
    runs at exactly ``rate`` does not drop every other sample.
    """

    def __init__(self, rate: float) -> None:
        self.period = 1.0 / rate if rate > 0 else 0.0
        self._due = -math.inf

    def ready(self, now: float) -> bool:
        if self.period == 0.0:
            return True
        if now < self._due - 0.5 * self.period:
            return False
        self._due = max(self._due + self.period, now + 0.5 * self.period)
        return True


# -- the node ----------------------------------------------------------------------------------


class DriverNode:
    """Publishers, subscribers and the tick loop around one :class:`DriverCore`."""

    def __init__(
        self, settings: NodeSettings, config: DriverConfig, link: Any,
        clock: Clock | None = None, *, core: DriverCore | None = None, wire: Any = None,
        lock: Any = None, ros: tuple[Any, Any] | None = None,
    ) -> None:
        """``core``: a DriverCore that already talks to its lower computer (the lockstep
        robot's, :mod:`lowerbase.robot.lockstep`; ``link`` and ``clock`` are then unused);
        ``wire``: how the face reaches ROS (:mod:`lowerbase.ros1.wire`; None: rospy as is);
        ``lock``: shared with the other faces of this process (None: one of its own);
        ``ros``: (rospy, message builders) to use instead of rospy and
        :mod:`lowerbase.driver.ros_io` (the ROS 2 face, :mod:`lowerbase.driver.ros2_node`)."""
        from lowerbase.ros1.wire import RosWire

        self.rospy: Any
        self.io: Any
        self.rospy, self.io = ros if ros is not None else import_ros()
        self.wire = wire if wire is not None else RosWire(self.rospy)
        self.settings = settings
        self.link = link
        self.lock = lock if lock is not None else threading.RLock()
        self.stop = threading.Event()
        self.core = core if core is not None else \
            DriverCore(link.send, clock or RealClock(self.stop), config)
        self._shared_core = core is not None
        #: how far behind its bus the reader runs (frames handled late: counted and warned of)
        self.lag = HandlingLag(self.core.stats)
        self.core.listeners.append(self._on_event)
        self._throttles = {k: Throttle(r) for k, r in settings.rates.items()}
        self._battery_dirty = False
        self._info_dirty = False
        self._published_state: LinkState | None = None
        self._pubs: dict[str, Any] = {}
        self._subs: list[Any] = []
        self._services: list[Any] = []
        self._bad_twists = WarnLimiter(self.core.config.malformed_log_period)  # refused twists
        self._tf: Any = None
        self._last_tf_stamp: Any = None  #: of the last odom -> base_link sent
        self._last_odom_stamp: float | None = None  #: [s] of the last /odom
        self._last_imu_stamp: float | None = None  #: [s] of the last /imu/data_raw
        self._last_battery_stamp: float | None = None  #: [s] of the last /battery
        self._reader: threading.Thread | None = None

    def ros_now(self) -> Any:
        """The ROS time stamps are taken at; with a shared core its clock's (the lockstep
        robot's simulated time is ROS time, and the core's clock is exact inside a batch)."""
        if self._shared_core:
            return self.rospy.Time.from_sec(self.core.clock.now())
        return self.rospy.Time.now()

    # -- set-up ------------------------------------------------------------------------------

    def advertise(self) -> None:
        """Create the publishers and subscribers named in the settings (after init_node)."""
        io, wire = self.io, self.wire
        specs: dict[str, tuple[Any, bool, int]] = {
            "odom_raw": (io.Odometry, False, 10), "odom": (io.Odometry, False, 10),
            "imu": (io.Imu, False, 20), "odom_twist": (io.Twist, False, 10),
            "odometer": (io.Float64, False, 5), "battery": (io.Battery, False, 2),
            "bms": (io.BMS, False, 2), "parameter": (io.Parameter, True, 1),
            "information": (io.Information, True, 1), "status_code": (io.UInt64, False, 5),
            "link_state": (io.String, True, 1),
        }
        topics = self.settings.topics
        for key, (cls, latch, depth) in specs.items():
            if topics[key]:
                self._pubs[key] = wire.publisher(topics[key], cls, queue_size=depth,
                                                 latch=latch)
        if self.settings.publish_tf:
            self._tf = wire.tf_broadcaster()
        subs: list[tuple[str, Any, Callable[[Any], None]]] = [
            ("base_cmd_vel", io.Twist, lambda m: self._on_twist(m, False)),
            ("smooth_cmd_vel", io.Twist, lambda m: self._on_twist(m, True)),
            ("rgbled", io.LED, lambda m: self._on_led(m, 0)),
            ("rgbled_shelf", io.LED, lambda m: self._on_led(m, 1)),
            ("rgbled_shelf_vendor", io.LED, lambda m: self._on_led(m, 1)),
        ]
        for key, cls, callback in subs:
            if topics[key]:
                self._subs.append(wire.subscriber(topics[key], cls, callback, queue_size=10))
        self._services = services.advertise(wire, self.core, self.lock)

    # -- ROS -> core -------------------------------------------------------------------------

    def _on_twist(self, msg: Any, smoothed: bool) -> None:
        linear, angular = self.io.twist_args(msg)
        with self.lock:
            if math.isfinite(linear) and math.isfinite(angular):
                self.core.set_twist(linear, angular, smoothed)
                return
            # refused here, not in the core, so that a NaN stream (20/s) is one line every
            # malformed_log_period seconds, with the count, instead of a line per twist
            self.core.stats["twist_rejected"] += 1
            said = self._bad_twists.take(self.core.clock.now())
            if said is not None:
                log.warning("ignored %d twist(s) with NaN or infinity, latest (%r, %r)",
                            said[0], linear, angular)

    def _on_led(self, msg: Any, strip: int) -> None:
        with self.lock:
            self.core.set_led(strip, **self.io.led_args(msg))

    # -- core -> ROS -------------------------------------------------------------------------

    def on_frame(self, frame_id: int, data: bytes) -> None:
        # stamped when the bus received it: a reader that fell behind (a busy host, this lock
        # held by the tick) hands a backlog over at once, and the core's timing checks (wheel
        # sample gaps, Uptime) must see the frames' spacing, not the burst
        received = getattr(self.link, "last_received", None)
        age = getattr(self.link, "last_age", 0.0)
        handed = time.time()
        with self.lock:  # held by the tick, which a busy host can deschedule for seconds
            # the frame's age as its stamp is taken: since the bus received it, the reader's
            # hand-over and the wait for this lock included
            wall = time.time()
            age = wall - received if received is not None else age + (wall - handed)
            if received is not None:
                self.lag.handled(age, wall)
            clock = self.core.clock
            ago = getattr(clock, "ago", None)
            stamp = ago(age) if ago is not None else clock.now() - age
            self.core.heard_until = stamp
            self.core.on_frame(frame_id, data, stamp)

    def on_idle(self) -> None:
        """The reader found the bus quiet: the core may count silence up to now."""
        with self.lock:
            self.core.heard_until = self.core.clock.now()

    def on_bus_down(self, why: str) -> None:
        with self.lock:
            self.core.bus_down(why)

    def _publish(self, key: str, msg: Any) -> None:
        pub = self._pubs.get(key)
        if pub is not None:
            pub.publish(msg)

    def _wants(self, key: str) -> bool:
        """Whether ``key``'s message would reach anyone (:func:`lowerbase.ros1.wire.wanted`;
        alone always): the lockstep robot builds no message nobody takes."""
        pub = self._pubs.get(key)
        return pub is not None and wanted(pub)

    def _on_event(self, what: str, core: DriverCore) -> None:
        """DriverCore listener (called under the lock, in the reader thread)."""
        now = core.clock.now()
        if what == "odometry":
            if self._throttles["odom"].ready(now):
                self._publish_odometry()
        elif what == "imu":
            if (core.imu is not None and self._throttles["imu"].ready(now)
                    and self._wants("imu")):
                gyro, accel = core.imu
                s = self.settings
                stamp, self._last_imu_stamp = self._stamp_at(core.imu_stamp,
                                                             self._last_imu_stamp)
                self._publish("imu", self.io.imu_msg(
                    stamp, s.imu_frame, gyro, accel,
                    s.imu_angular_velocity_variance, s.imu_linear_acceleration_variance))
        elif what == "twist":
            if self._throttles["odom_twist"].ready(now) and self._wants("odom_twist"):
                self._publish("odom_twist", self.io.twist_msg(*core.measured_twist))
        elif what == "odometer":
            if self._throttles["odometer"].ready(now) and self._wants("odometer"):
                self._publish("odometer", self.io.Float64(data=core.odometer))
        elif what == "status_code":
            if self._throttles["status_code"].ready(now) and self._wants("status_code"):
                self._publish("status_code", self.io.status_code_msg(core.status_code))
        elif what == "battery":
            self._battery_dirty = True
        elif what in ("parameters", "information", "ready"):
            self._info_dirty = True

    def _sample_stamp(self) -> Any:
        """ROS time of the odometry's sample (the EKF's stamp, aged on the core's clock), not
        of publishing: the world and navigation pair scans with /odom by stamp, and a frame
        handled late (a backlog at K=2) was stamped up to 2 s of /clock after its motion."""
        stamp, self._last_odom_stamp = self._stamp_at(self.core.ekf.stamp,
                                                      self._last_odom_stamp)
        return stamp

    def _stamp_at(self, at: float | None, last: float | None) -> tuple[Any, float]:
        """The ROS time of a sample taken at ``at`` [s, the core's clock: its frame's receive
        stamp], aged from now, and that time [s]: a reader that fell behind (a busy host)
        publishes a backlog at once, and its samples keep their own times. Never before
        ``last`` (the previous one's); with no believable age (none, or above
        :data:`MAX_STAMP_AGE`), now."""
        now = self.ros_now()
        age = self.core.clock.now() - at if at is not None else math.nan
        stamp = now - self.rospy.Duration.from_sec(age) if 0.0 < age <= MAX_STAMP_AGE else now
        sec = stamp.to_sec()
        if last is not None and last - MAX_STAMP_AGE < sec < last:
            stamp = self.rospy.Time.from_sec(last)  # never back (after an EKF reset, "now")
            sec = stamp.to_sec()
        return stamp, sec

    def _publish_odometry(self) -> None:
        core, io, s = self.core, self.io, self.settings
        stamp = self._sample_stamp()
        odo = core.odometry
        if odo is not None and self._wants("odom_raw"):
            self._publish("odom_raw", io.odometry_msg(
                stamp, s.odom_frame, s.base_frame, (odo.x, odo.y, odo.yaw),
                (odo.linear, odo.angular), odo.pose_covariance, odo.twist_covariance,
                core.config.odometry_noise.unobserved_variance))
        ekf = core.ekf
        pose = ekf.pose
        pub = self._pubs.get("odom")
        if pub is not None:
            # built only if read: in lockstep the faces here take the pose (ODOM_POSE), and
            # the message is made only when a node outside takes /odom (publish_lazy)
            twist, unobserved = ekf.twist, core.config.odometry_noise.unobserved_variance
            pose_cov, twist_cov = ekf.covariances()
            self.wire.publish_lazy(
                pub, io.odom_header(stamp, s.odom_frame),
                lambda: io.odometry_msg(stamp, s.odom_frame, s.base_frame, pose, twist,
                                        [float(v) for v in pose_cov.ravel()],
                                        [float(v) for v in twist_cov.ravel()], unobserved),
                {io.ODOM_POSE: lambda: io.odom_pose_of(pose)})
        # under /use_sim_time two samples can share one /clock tick: tf2 drops the second
        # (TF_REPEATED_DATA in every listener's log), so it is not sent
        if self._tf is not None and stamp != self._last_tf_stamp:
            self._last_tf_stamp = stamp
            self._tf.sendTransform(io.odom_transform(stamp, s.odom_frame, s.base_frame, pose))

    def publish_periodic(self) -> None:
        """What the main loop publishes: battery/BMS, parameters/information, link state."""
        core, io = self.core, self.io
        now = core.clock.now()
        if self._battery_dirty and self._throttles["battery"].ready(now):
            self._battery_dirty = False
            battery, bms = core.bms.battery_fields(), core.bms.bms_fields()
            stamp, self._last_battery_stamp = self._stamp_at(core.bms_stamp,
                                                             self._last_battery_stamp)
            if battery is not None and bms is not None:
                self._publish("battery", io.battery_msg(stamp, battery))
                self._publish("bms", io.bms_msg(stamp, bms))
        if self._info_dirty and io.parameter_complete(core.parameters):
            self._info_dirty = False
            stamp = self.ros_now()
            self._publish("parameter", io.parameter_msg(stamp, core.parameters))
            if len(core.versions) == 4:
                self._publish("information", io.information_msg(stamp, core.information()))
            else:
                self._info_dirty = True  # versions still coming: publish once complete
        if core.state != self._published_state:
            self._published_state = core.state
            self._publish("link_state", io.String(data=core.state.value))
            print(f"lowerbase driver: link {core.state.value}", flush=True)

    # -- running -----------------------------------------------------------------------------

    def start_reader(self) -> None:
        self._reader = threading.Thread(target=self._read, name="driver_base-reader",
                                        daemon=True)
        self._reader.start()

    def _read(self) -> None:
        try:
            self.link.run_reader(self.on_frame, self.stop, self.on_bus_down,
                                 on_idle=self.on_idle)
        except Exception:  # never let the reader die silently
            log.exception("the frame reader failed")
            self.rospy.signal_shutdown("frame reader failed")

    def step(self) -> None:
        """One period of the main loop: tick the core, publish the periodic topics."""
        with self.lock:
            self.core.tick()
            self.publish_periodic()

    def spin(self) -> None:
        """Run until rospy shuts down (Ctrl-C, SIGTERM, rosnode kill) or ``stop`` is set."""
        from lowerbase.driver.rostime import Pacer

        rospy = self.rospy
        rospy.on_shutdown(self.stop.set)
        # on the core's clock: wall time, or ROS time under /use_sim_time (driver.rostime)
        pacer = Pacer(self.core.clock, 1.0 / self.core.config.command_rate, self.stop)
        while not self.stop.is_set() and not rospy.is_shutdown():
            self.step()
            pacer.wait()

    def shutdown(self) -> None:
        """Stop the reader, send one stop if a twist is being commanded, close the link."""
        self.stop.set()
        if self._reader is not None:
            self._reader.join(timeout=3.0)
        with self.lock:
            if self.core.commanding:
                self.core.set_twist(0.0, 0.0)
        for sub in self._subs:
            sub.unregister()
        for service in self._services:
            service.shutdown()
        self.link.close()


def run(
    link_factory: Callable[[Callable[[], None]], Any], ros_args: Sequence[str],
    *, name: str = NODE_NAME, params: dict[str, Any] | None = None,
) -> int:
    """Start rospy, build the node on the link ``link_factory(on_finished)`` and spin.

    ``ros_args`` are remappings and special keys (``__name:=``, ``__ns:=``, ``_param:=``),
    as ``rospy.myargv`` leaves them out. ``params`` override the private parameters (tests).
    """
    import_ros()  # one line if ROS or woosh_msgs are missing
    from lowerbase.driver.settings import load_settings
    from lowerbase.ros1.node import ros_session

    with contextlib.suppress(AttributeError, ValueError):
        sys.stdout.reconfigure(line_buffering=True)  # type: ignore[union-attr]
    with ros_session("driver", name, ros_args) as session:
        rospy = session.rospy
        if session.loopback is not None:
            print(f"lowerbase driver: listening on loopback only (ROS_IP={session.loopback}); "
                  "set ROS_IP or ROS_HOSTNAME to this host's address to serve other hosts",
                  flush=True)
        private = rospy.get_param("~", {})
        settings, config = load_settings({**private, **(params or {})})
        node: DriverNode | None = None

        def finished() -> None:
            print("lowerbase driver: replay finished", file=sys.stderr, flush=True)
            rospy.signal_shutdown("replay finished")

        link = link_factory(finished)
        try:
            from lowerbase.driver import rostime

            clock: Clock | None = None
            if rostime.uses_sim_time(rospy):  # the core and the loop on /clock's time
                clock = rostime.RosClock(rospy)
                if not rostime.wait_for_clock(rospy, clock.stop):
                    return 0
            node = DriverNode(settings, config, link, clock=clock)
            if clock is not None:  # frames handled late lag /clock K x as much (K x real time)
                node.core.allow_receive_lag(config.link_timeout)
            node.advertise()
            node.start_reader()
            session.announce(f"link {link.description}")
            node.spin()
        finally:
            if node is not None:
                node.shutdown()
                session.stopped(node.core.stats)
            else:
                link.close()
    return 0
