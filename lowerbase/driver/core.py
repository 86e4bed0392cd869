"""driver_base without ROS: frames in, chassis state out, commands back.

``DriverCore`` is everything the ROS node does except talking to ROS: it decodes the lower
computer's frames, reads the parameters from the lower computer at start (and again after a
reboot), enables CAN control, integrates wheel odometry (/odom_raw) and runs the EKF (/odom),
keeps the IMU, battery, BMS, parameter, version and status state, and turns twists and LED
requests into frames. The ROS node, the benches and the demo all drive this one class; time
comes from the injected clock.
Its parts: the definitions (core_defs: LinkState, DriverConfig, re-exported here), the link's
life cycle (core_link: Heartbeats, reboots, parameters, enabling), wheel and gyro input
(core_odom), the status frames (core_status); this module dispatches frames, sends and ticks.

Reboots are decided from consistent evidence: the Heartbeat's Uptime runs with the receiver's
clock; a Heartbeat whose Uptime is well *behind* that timeline (it went backwards, or is
smaller than a silence that just ended) makes a reboot suspected, and the next Heartbeat
confirms it if it continues the *new* timeline. Only then are the parameters read again and
CAN control re-enabled (``auto_enable``). Odometry never integrates across an outage: a lost
link holds /odom_raw and /odom (velocities 0), and wheel counts after a lost link, a suspected
reboot, a long gap or a Counter that ran ahead of the time elapsed are a new baseline, not
motion; a late sender (fewer cycles than time, then a catch-up burst) is integrated, each
sample stamped on the sender's time base (the Counter's cycles). A changed
BootCounter with the Uptime still counting (a garbled or forged frame) is counted and ignored.
Control is enabled at first contact and after a confirmed reboot only, retried until
SystemStatus shows ControlMode Can; a chassis put in standby (or e-stopped) on purpose is
never re-enabled. ``state`` is ``ready`` only
while the chassis takes commands (ControlMode Can); configured but in standby is ``standby``.

MotionCommand runs on a fixed grid of 1/command_rate (the DBC's 20 ms cycle): a tick sends
when its slot is due (from half a period early), the slot then advances by exactly one
period; a new twist goes out at once when it starts a command or its slot is within half a
period, else in the next slot, so the rate stays at command_rate however ticks and twists
jitter.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable
from typing import Any

from lowerbase.bms.frames import BmsFrameAccumulator
from lowerbase.clock import Clock, WarnLimiter
from lowerbase.driver.core_defs import (
    _ESTOP_BITS,
    HOLD_COMMANDS,
    ODOMETRY_PARAMETERS,
    RELEASE_GRACE,
    UPTIME_SLACK,
    VERSION_FIELDS,
    DriverConfig,
    LinkState,
    Send,
)
from lowerbase.driver.core_link import LinkLifecycle
from lowerbase.driver.core_status import StatusInput
from lowerbase.driver.ekf import PlanarEkf
from lowerbase.driver.odometry import WheelOdometry
from lowerbase.errors import ProtocolError, UnknownMessageError
from lowerbase.protocol.codec import Codec, default_codec
from lowerbase.transport.peers import PeerMonitor

__all__ = ["HOLD_COMMANDS", "ODOMETRY_PARAMETERS", "RELEASE_GRACE", "UPTIME_SLACK",
           "VERSION_FIELDS", "DriverConfig", "DriverCore", "LinkState", "Listener", "Send"]

log = logging.getLogger(__name__)

#: a status listener: ``(what changed, the core)``
Listener = Callable[[str, "DriverCore"], None]


class DriverCore(LinkLifecycle, StatusInput):
    """See the module docstring. Feed ``on_frame``; call ``tick`` at least at command_rate."""

    def __init__(
        self, send: Send, clock: Clock, config: DriverConfig | None = None,
        codec: Codec | None = None,
    ) -> None:
        self._send = send
        self.clock = clock
        #: the time up to which every frame that arrived has been handed to :meth:`on_frame`
        #: (set by a receiver thread; None: always now, as on a simulated loop)
        self.heard_until: float | None = None
        self.config = config or DriverConfig()
        self.codec = codec or default_codec()
        # frame ID -> (compiled decoder, handler or None, sent by the lower computer): one
        # dict lookup per frame instead of a catalog lookup and a getattr by name
        self._dispatch: dict[int, tuple[Callable[[bytes, bool], tuple[str, Any]],
                                        Callable[[dict[str, Any], float], None] | None,
                                        bool]] = {}
        for frame_id, decode in self.codec.decoders().items():
            msg = self.codec.message(frame_id)
            self._dispatch[frame_id] = (decode, getattr(self, f"_on_{msg.name}", None),
                                        "Lower" in msg.senders)
        mc = self.codec.message("MotionCommand")
        #: the wire range of MotionCommand's Linear [m/s] and Angular [rad/s]
        self._twist_range = tuple(
            (float(mc.signal(n).minimum or 0.0), float(mc.signal(n).maximum or 0.0))
            for n in ("Linear", "Angular"))
        self.stats: Counter[str] = Counter()
        self.listeners: list[Listener] = []
        self._counters: Counter[str] = Counter()
        #: message name -> (its codec, its stats key): looked up once per name
        self._tx: dict[str, tuple[Any, str, bool]] = {}
        self._param_names = self.codec.message("ParameterRequest").signal("Index").choices
        self.state = LinkState.WAITING
        self.boot_counter: int | None = None
        self.reboots = 0
        self._uptime: tuple[float, float] | None = None  # (Uptime, receive time) of the last
        self._reboot_suspect: tuple[float, float, int] | None = None  # (Uptime, time, boot)
        self._overruns = 0  # the last Heartbeat's Overruns (the lower computer's slips, mod 16)
        self._configured_ok = False
        self._control_can: bool | None = None  # ControlMode Can in the latest SystemStatus
        self._enable_wanted = False  # first contact or a confirmed reboot, not enabled yet
        #: the operator put the chassis on hold (EStopSet, Standby) and has not enabled it
        #: since: a reboot does not end the hold (no automatic enable after it)
        self.operator_hold = False
        self._estop_release_sent = -math.inf
        self._last_enable = -math.inf
        #: notices a second lower computer on the bus (warned once, stats two_lower_computers)
        self.peers = PeerMonitor(self.codec)
        #: [s] how far a Heartbeat's Uptime may stray from this clock (:meth:`allow_receive_lag`)
        self.uptime_slack = UPTIME_SLACK
        self.parameters: dict[str, float] = {}
        self.versions: dict[str, str] = {}
        self._version_parts: dict[int, dict[int, bytes]] = {}
        self.odometry: WheelOdometry | None = None
        self.ekf = PlanarEkf(self.config.ekf_noise)
        self.imu: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
        self.imu_stamp = 0.0
        self.bms = BmsFrameAccumulator()
        self.bms_stamp: float | None = None  #: [s] when the last whole BMS burst came
        self.status_code = 0
        self.system_status: dict[str, Any] = {}
        self.measured_twist = (0.0, 0.0)
        self.odometer = 0.0
        self.leds: dict[tuple[int, int], dict[str, int]] = {}
        self._wheels: dict[int, tuple[int, int]] = {}
        self._wheel_period = self.codec.message("WheelFeedback").cycle_time or 0.02
        self._last_wheel: tuple[float, int] | None = None  # (time, rolling Counter)
        self._last_counts: tuple[int, int] | None = None  # its (left, right) counts
        self._wheels_done: tuple[int, int] | None = None  # the pair being taken
        self._wheel_speeds = (0.0, 0.0)  # [m/s] left, right over the last interval
        #: [s] the last wheel sample's time on the sender's time base (see _wheel_stamp)
        self._wheel_time = -math.inf
        #: the next wheel sample is a new baseline, not motion (link lost, reboot suspected)
        self._odom_gap = False
        self._last_heartbeat = -math.inf
        self._last_request = -math.inf
        self._twist: tuple[float, float, bool] | None = None
        self._twist_stamp = -math.inf
        self._next_command = -math.inf
        self._stale_sent = True
        self._malformed_log = WarnLimiter(self.config.malformed_log_period)

    # -- inputs from the upper side ------------------------------------------------------------

    def set_twist(self, linear: float, angular: float, smoothed: bool = False) -> bool:
        """A twist from /base_cmd_vel (raw) or /smooth_cmd_vel (smoothed). False if refused."""
        if not (math.isfinite(linear) and math.isfinite(angular)):
            self.stats["twist_rejected"] += 1
            log.warning("ignored a twist with NaN or infinity (%r, %r)", linear, angular)
            return False
        (lo_v, hi_v), (lo_w, hi_w) = self._twist_range
        clipped = (min(max(linear, lo_v), hi_v), min(max(angular, lo_w), hi_w))
        if clipped != (linear, angular):
            self.stats["twist_clipped"] += 1
        now = self.clock.now()
        idle = self._twist is None
        self._twist = (clipped[0], clipped[1], smoothed)
        self._twist_stamp = now
        self._stale_sent = False
        if idle:  # a new command goes out at once (latency matters) and starts the grid
            self._next_command = now
        if now >= self._next_command - 0.5 / self.config.command_rate:
            self._send_motion(now)  # else it goes out in the next slot, in < half a period
        return True

    def set_led(self, strip: int, submodule: int, urgency: int, abnormal: int, normal: int,
                color: int) -> bool:
        """woosh_msgs/LED on rgbled (strip 0) or rgbled_shelf (strip 1). False if invalid."""
        try:
            self._emit("LedCommand", {"Strip": strip, "Submodule": submodule,
                                      "Urgency": urgency, "Abnormal": abnormal,
                                      "Normal": normal, "Color": color})
        except ProtocolError as exc:
            self.stats["led_rejected"] += 1
            log.warning("ignored an LED request: %s", exc)
            return False
        return True

    def control(self, command: str) -> None:
        """Send a ControlCommand by name (EnableCanControl, EStopSet, FaultClear, ...)."""
        if command in HOLD_COMMANDS:
            self.operator_hold = True
        elif command == "EnableCanControl":
            self.operator_hold = False
        elif command == "EStopRelease":
            self._estop_release_sent = self.clock.now()
        self._emit("ControlCommand", {"Command": command})

    def write_parameter(self, name: str, value: float) -> None:
        index = next(i for i, n in self._param_names.items() if n == name)
        self._emit("ParameterRequest", {"Index": index, "Op": 1, "Value": value})

    # -- frames from the lower computer ------------------------------------------------------

    def on_frame(self, frame_id: int, data: bytes, stamp: float | None = None) -> None:
        """Handle one frame. Unknown and malformed frames are counted and logged, not raised."""
        now = self.clock.now() if stamp is None else stamp
        self.stats["frames"] += 1
        entry = self._dispatch.get(frame_id)
        if entry is None:
            self._malformed(frame_id, UnknownMessageError(f"unknown ID {frame_id:#05x}"), now)
            return
        decode, handler, from_lower = entry
        try:
            _name, values = decode(data, True)
        except ProtocolError as exc:
            self._malformed(frame_id, exc, now)
            return
        if not from_lower:
            return  # our own commands, heard back on a shared bus
        if frame_id == self.peers.heartbeat_id and self.peers.on_frame(frame_id, data, now):
            self.stats["two_lower_computers"] += 1
            log.warning("%s", self.peers.warning)
            self._notify("two_lower_computers")
        if handler is not None:
            handler(values, now)
        if self.state == LinkState.LOST and now - self._last_heartbeat <= \
                self.config.link_timeout:  # back with a Heartbeat (or a bus reopened)
            log.info("lower computer link is back")
            self._settle()

    def bus_down(self, why: str) -> None:
        """The link's bus failed (a device unplugged): the link is lost until frames return."""
        self.stats["bus_down"] += 1
        self._control_can = None  # learn the chassis' state afresh when frames return
        if self.state != LinkState.LOST:
            self._hold_odometry(self._watchdog_time())
            self.state = LinkState.LOST
            self.stats["link_lost"] += 1
            log.warning("lower computer link lost: %s", why)
            self._notify("link")

    def _settle(self) -> None:
        """The state the link is in when it is up: configuring, standby or ready."""
        if not self._configured_ok or self.odometry is None:
            state = LinkState.CONFIGURING
        elif self._control_can is None:
            state = LinkState.CONFIGURING if self.state == LinkState.CONFIGURING \
                else LinkState.STANDBY
        else:
            state = LinkState.READY if self._control_can else LinkState.STANDBY
        if state != self.state:
            self.state = state
            self._notify("link")

    def _malformed(self, frame_id: int, exc: Exception, now: float) -> None:
        self.stats["malformed"] += 1
        said = self._malformed_log.take(now)
        if said is not None:
            log.warning("%d malformed frame(s) dropped, latest ID 0x%03X: %s", said[0],
                        frame_id, exc)

    # -- periodic work -----------------------------------------------------------------------

    def tick(self) -> None:
        """Send what is due: motion commands, configuration requests; watch the link."""
        now = self.clock.now()
        # silence counts only as far as the receiver has listened (a starved reader thread has a
        # backlog of Heartbeats waiting, not a lost link)
        heard = now if self.heard_until is None else min(now, self.heard_until)
        silent = heard - self._last_heartbeat > self.config.link_timeout
        if silent and self.state not in (LinkState.WAITING, LinkState.LOST):
            self._hold_odometry(self._watchdog_time())
            self.state = LinkState.LOST
            self._control_can = None  # learn the chassis' state afresh when frames return
            self.stats["link_lost"] += 1
            log.warning("lower computer link lost: no Heartbeat for %.1f s",
                        now - self._last_heartbeat)
            self._notify("link")
        if self.state == LinkState.CONFIGURING and now - self._last_request >= \
                self.config.request_retry:
            self._last_request = now
            for index, name in self._param_names.items():
                if name not in self.parameters:
                    self._emit("ParameterRequest", {"Index": index, "Op": 0, "Value": 0.0})
            if len(self.versions) < len(VERSION_FIELDS):
                self._emit("VersionRequest", {"Field": 0})
        if (self._enable_wanted and self.state == LinkState.STANDBY
                and now - self._last_enable >= self.config.request_retry):
            self._enable()  # the first EnableCanControl was lost, or came during boot
        if self._twist is None:
            return
        period = 1.0 / self.config.command_rate
        fresh = now - self._twist_stamp < self.config.command_timeout
        if fresh and now >= self._next_command - 0.5 * period:
            self._send_motion(now)
        elif not fresh and not self._stale_sent:
            self._stale_sent = True
            self._twist = (0.0, 0.0, self._twist[2])
            self._send_motion(now)  # one explicit stop; the lower computer's watchdog backs it
            self._twist = None
            self.stats["twist_stale"] += 1

    def quiet_ticks(self, start: float, dt: float, limit: int) -> int:
        """How many of the ticks at ``start``, ``start + dt``, ... (a SimClock's times) find
        the link up, as far as the state now tells (Heartbeats only move the link's last one
        later), at most ``limit``: 0 unless READY and not enabling. Their sends depend on the
        twist and the command grid alone, so SimLoop runs them ahead of the MCU's frames."""
        if self.state is not LinkState.READY or self._enable_wanted:
            return 0
        heartbeat, link_timeout = self._last_heartbeat, self.config.link_timeout
        now = start
        for k in range(limit):
            if now - heartbeat > link_timeout:
                return k
            now += dt
        return limit

    def _send_motion(self, now: float) -> None:
        assert self._twist is not None
        v, w, smoothed = self._twist
        self._emit("MotionCommand", {"Linear": v, "Angular": w,
                                     "Mode": "Smoothed" if smoothed else "Raw"})
        period = 1.0 / self.config.command_rate
        self._next_command += period  # the next slot of a fixed grid
        if self._next_command < now:  # far behind (a stall): resync, do not burst
            self._next_command = now + period

    def _emit(self, name: str, values: dict[str, Any]) -> None:
        tx = self._tx.get(name)
        if tx is None:
            msg = self.codec.message(name)
            tx = self._tx[name] = (msg, f"tx_{name}", msg.has_counter)
        msg, key, has_counter = tx
        if has_counter:
            values["Counter"] = self._counters[name] & 0xF
            self._counters[name] += 1
        data = msg.encode(values)
        self.stats[key] += 1
        self._send(msg.frame_id, data)

    def _notify(self, what: str) -> None:
        for listener in self.listeners:
            listener(what, self)

    # -- views -------------------------------------------------------------------------------

    @property
    def commanding(self) -> bool:
        """True while a twist is being sent (fresh, or its final stop not sent yet)."""
        return self._twist is not None

    @property
    def e_stopped(self) -> bool:
        """The chassis shows an e-stop (button or command) and no EStopRelease was just sent."""
        shown = self.system_status.get("RobotState") in (3, "EmergencyStop") or bool(
            self.status_code & _ESTOP_BITS)
        return shown and self.clock.now() - self._estop_release_sent > RELEASE_GRACE

    @property
    def link_up(self) -> bool:
        return self.state in (LinkState.CONFIGURING, LinkState.STANDBY, LinkState.READY)

    def information(self) -> dict[str, Any]:
        """woosh_msgs/Information fields (without header)."""
        return {**{name: self.versions.get(name, "") for name in VERSION_FIELDS.values()},
                "parameter": dict(self.parameters)}
