"""driver_base without ROS: frames in, chassis state out, commands back.

``DriverCore`` is everything the ROS node does except talking to ROS: it decodes the lower
computer's frames, reads the parameters from the lower computer at start (and again after a
reboot), enables CAN control, integrates wheel odometry (/odom_raw) and runs the EKF (/odom),
keeps the IMU, battery, BMS, parameter, version and status state, and turns twists and LED
requests into frames. The ROS node, the benches and the demo all drive this one class; time
comes from the injected clock.

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

import enum
import logging
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from lowerbase.bms.frames import BmsFrameAccumulator
from lowerbase.clock import Clock
from lowerbase.driver.ekf import EkfNoise, PlanarEkf
from lowerbase.driver.odometry import OdometryNoise, OdometryParameters, WheelOdometry
from lowerbase.errors import LowerbaseError, ProtocolError, UnknownMessageError
from lowerbase.protocol.codec import Codec, default_codec
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.transport.peers import PeerMonitor

log = logging.getLogger(__name__)

_IMU_FAULT = int(StatusBit.IMU_FAULT)

#: the woosh_msgs/Parameter fields the odometry needs before it can run
ODOMETRY_PARAMETERS = ("wheelPerimeter", "wheelDistant", "ratioLeft", "ratioRight",
                       "pulsePerCircle")
VERSION_FIELDS = {1: "hardwareVersion", 2: "softwareVersion", 3: "IAPSoftwareVersion",
                  4: "movebaseType"}


class LinkState(enum.Enum):
    WAITING = "waiting"  #: nothing heard from the lower computer yet
    CONFIGURING = "configuring"  #: reading parameters
    STANDBY = "standby"  #: configured, but the chassis ignores commands (not in CAN control)
    READY = "ready"  #: parameters read, odometry running, the chassis in CAN control
    LOST = "lost"  #: no Heartbeat within link_timeout


@dataclass(frozen=True)
class DriverConfig:
    """Tuning of the driver core (the ROS node sets these from ROS parameters)."""

    command_rate: float = 50.0  #: [Hz] MotionCommand rate while the last twist is fresh
    command_timeout: float = 0.5  #: [s] a twist older than this is stale: stop sending
    link_timeout: float = 1.5  #: [s] no Heartbeat this long: the link is lost
    request_retry: float = 0.5  #: [s] parameter/version requests repeated this often
    auto_enable: bool = True  #: enable CAN control once configured (and after a reboot)
    malformed_log_period: float = 5.0  #: [s] malformed frames are logged at most this often
    #: wheel samples further apart than this many WheelFeedback cycles are a gap: the counts
    #: after it are a new baseline, not motion (a missed reboot, a stalled reader). Below it,
    #: the 4-bit rolling Counter must agree with the time elapsed (frames lost, not a reboot)
    wheel_gap_cycles: float = 12.0
    odometry_noise: OdometryNoise = field(default_factory=OdometryNoise)
    ekf_noise: EkfNoise = field(default_factory=EkfNoise)
    gyro_sigma: float | None = None  #: [rad/s] per-sample gyro noise for the EKF (None: ekf's)

    def __post_init__(self) -> None:
        for name in ("command_rate", "command_timeout", "link_timeout", "request_retry",
                     "wheel_gap_cycles"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise LowerbaseError(f"driver {name} must be > 0, got {value!r}")


#: [s] how far a Heartbeat's Uptime may stray from the receiver's clock (plus 2 % of the gap)
UPTIME_SLACK = 0.5
_ESTOP_OR_FAULT = (3, 4, "EmergencyStop", "Fault")  # SystemStatus RobotState
_ESTOP_BITS = int(StatusBit.ESTOP_BUTTON | StatusBit.ESTOP_COMMAND)
#: commands that put the chassis on hold on purpose: no automatic enable until EnableCanControl
HOLD_COMMANDS = ("EStopSet", "Standby")
#: [s] after an EStopRelease is sent the chassis counts as released (its status follows)
RELEASE_GRACE = 0.3

Send = Callable[[int, bytes], None]
Listener = Callable[[str, "DriverCore"], None]


class DriverCore:
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
        self.status_code = 0
        self.system_status: dict[str, Any] = {}
        self.measured_twist = (0.0, 0.0)
        self.odometer = 0.0
        self.leds: dict[tuple[int, int], dict[str, int]] = {}
        self._wheels: dict[int, tuple[int, int]] = {}
        self._wheel_period = self.codec.message("WheelFeedback").cycle_time or 0.02
        self._last_wheel: tuple[float, int] | None = None  # (time, rolling Counter)
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
        self._last_malformed_log = -math.inf
        self._malformed_since_log = 0

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
        self._malformed_since_log += 1
        if now - self._last_malformed_log >= self.config.malformed_log_period:
            log.warning("%d malformed frame(s) dropped, latest ID 0x%03X: %s",
                        self._malformed_since_log, frame_id, exc)
            self._last_malformed_log = now
            self._malformed_since_log = 0

    def _on_Heartbeat(self, v: dict[str, Any], now: float) -> None:
        self._last_heartbeat = now
        boot, uptime = int(v["BootCounter"]), float(v["Uptime"])
        if self.boot_counter is None or self._uptime is None:
            self.boot_counter, self._uptime = boot, (uptime, now)
            self._enable_wanted = self.config.auto_enable
            self._configure("first contact")
            return
        if _continues(self._uptime, uptime, now, self.uptime_slack):
            self._uptime = (uptime, now)
            if self._reboot_suspect is not None:
                self._reboot_suspect = None
                self.stats["heartbeat_inconsistent"] += 1
            if boot != self.boot_counter:
                self.stats["heartbeat_inconsistent"] += 1
                log.warning("a Heartbeat with BootCounter %d (not %d) but the Uptime still "
                            "counting: not a reboot, ignored (garbled or forged?)", boot,
                            self.boot_counter)
            return
        suspect = self._reboot_suspect
        if suspect is not None and _continues(suspect[:2], uptime, now, self.uptime_slack) \
                and boot == suspect[2]:
            behind = uptime < self._uptime[0] + (now - self._uptime[1])
            self._reboot_suspect = None
            self.boot_counter, self._uptime = boot, (uptime, now)
            if behind:
                self.reboots += 1
                log.warning("the lower computer rebooted (boot #%d, up %.1f s): reading "
                            "parameters again%s", boot, uptime, "; kept in standby (the "
                            "operator's hold: call ~enable)" if self.operator_hold else "")
                self._enable_wanted = self.config.auto_enable and not self.operator_hold
                self._configure("reboot")
            else:  # ahead of the old timeline: not a reboot; follow the new one
                self.stats["heartbeat_timeline_jump"] += 1
                log.warning("the lower computer's Uptime jumped ahead to %.1f s", uptime)
            return
        self._reboot_suspect = (uptime, now, boot)
        self.stats["heartbeat_off_timeline"] += 1
        self._hold_odometry(0.0)  # counters may restart: the next sample is a baseline

    def allow_receive_lag(self, seconds: float) -> None:
        """Take Heartbeats handled up to ``seconds`` late on this core's clock for the same
        lower computer (not a reboot, a jump or a second one). For ROS sim time: at K x real
        time a backlog of frames 1/K as long puts their Uptime that far behind /clock."""
        self.uptime_slack = max(UPTIME_SLACK, seconds)
        self.peers.tolerance = max(self.peers.tolerance, seconds)

    def _configure(self, why: str) -> None:
        self.state = LinkState.CONFIGURING
        self._configured_ok = False
        self.parameters = {}
        self.versions = {}
        self._version_parts = {}
        self._wheels = {}
        if self.odometry is not None:
            self.odometry.reset_baseline()  # counters restart at 0 after a reboot
        self._last_request = -math.inf
        self._notify("configuring")
        log.info("configuring (%s)", why)

    def _on_ParameterResponse(self, v: dict[str, Any], now: float) -> None:
        name = self._param_names.get(int(v["Index"]))
        if name is None:
            return
        if int(v["Result"]) != 0:
            self.stats["parameter_nack"] += 1
            log.warning("parameter %s: nack %d", name, int(v["Result"]))
        self.parameters[name] = float(v["Value"])
        if self.state == LinkState.CONFIGURING and set(self._param_names.values()) <= set(
            self.parameters
        ):
            self._configured()
        elif self.state == LinkState.READY:
            self._apply_parameters()
        self._notify("parameters")

    def _wheel_gap(self, counter: int, now: float) -> str | None:
        """Why this wheel sample must not be integrated against the last one (None: it may)."""
        if self._odom_gap or self.state == LinkState.LOST:
            return "link lost or reboot suspected"
        if self._last_wheel is None:
            return None
        dt = now - self._last_wheel[0]
        cycles = dt / self._wheel_period
        if cycles > self.config.wheel_gap_cycles:
            return f"no wheel sample for {dt:.2f} s"
        if (counter - self._last_wheel[1]) % 16 > cycles + 2.0:
            # more cycles than the time allows; fewer is a late sender (it catches up next)
            return "WheelFeedback Counter discontinuity"
        return None

    def _wheel_stamp(self, counter: int, now: float) -> float:
        """[s] when this wheel sample was taken, on the sender's time base: the last one's time
        plus the Counter's cycles, when that disagrees with the receive time ``now`` by more than
        half a cycle (a sender that ran late and now catches up sends its cycles in a burst),
        never after ``now``; back on ``now`` when it falls behind by more than the gap limit (a
        sender whose clock runs slow). Velocities and the EKF then see the cycles' true spacing,
        not the burst's."""
        if self._last_wheel is None or not math.isfinite(self._wheel_time):
            return now
        period = self._wheel_period
        stamp = self._wheel_time + (counter - self._last_wheel[1]) % 16 * period
        if abs(stamp - now) <= 0.5 * period or stamp > now:
            return now
        if now - stamp > self.config.wheel_gap_cycles * period:
            self.stats["wheel_time_reanchored"] += 1
            return now
        self.stats["wheel_late_samples"] += 1
        return stamp

    def _watchdog_time(self) -> float:
        """[s] how long the base may go on moving unseen: its watchdog, then braking."""
        v = abs(self.ekf.twist[0])
        decel = max(self.parameters.get("linearDecelLimit", 1.0), 0.1)
        return self.parameters.get("commandTimeout", 0.5) + v / (2.0 * decel)

    def _hold_odometry(self, unknown_time: float) -> None:
        """Stop integrating: hold both poses, zero the velocities, re-baseline the next
        sample. The base may move ``unknown_time`` [s] unseen: the EKF's pose variance says so."""
        self._odom_gap = True
        if self.odometry is not None:
            self.odometry.hold()
        v, w = self.ekf.twist
        self.ekf.hold(abs(v) * unknown_time, abs(w) * unknown_time)

    def _configured(self) -> None:
        self._apply_parameters()
        self._configured_ok = True
        log.info("lower computer configured: %s", ", ".join(
            f"{k}={self.parameters[k]:g}" for k in ODOMETRY_PARAMETERS))
        if self._enable_wanted:
            self._enable()
        self._notify("ready")  # configured (the link state says whether commands are taken)
        self._settle()

    def _enable(self) -> None:
        self._last_enable = self.clock.now()
        self.control("EnableCanControl")

    def _apply_parameters(self) -> None:
        params = OdometryParameters.from_lower_computer(self.parameters)
        # a count jump faster than the drive train can turn is a counter reset, not motion
        top_rpm = self.parameters.get("maxRPM", 3000.0)
        ratio = min(params.ratio_left, params.ratio_right)
        max_wheel_speed = 1.5 * top_rpm / 60.0 / ratio * params.wheel_perimeter
        if self.odometry is None:
            self.odometry = WheelOdometry(params, self.config.odometry_noise,
                                          max_wheel_speed=max_wheel_speed)
        else:
            self.odometry.max_wheel_speed = max_wheel_speed
            if self.odometry.params != params:
                self.odometry.params = params
                self.odometry.reset_baseline()

    def _on_VersionResponse(self, v: dict[str, Any], now: float) -> None:
        field_no = int(v["Field"])
        parts = self._version_parts.setdefault(field_no, {})
        parts[int(v["Sequence"])] = int(v["Text"]).to_bytes(6, "little")
        if int(v["Last"]) and len(parts) == int(v["Sequence"]) + 1:
            text = b"".join(parts[i] for i in range(len(parts))).rstrip(b"\0")
            self.versions[VERSION_FIELDS[field_no]] = text.decode("ascii", "replace")
            self._version_parts.pop(field_no, None)
            self._notify("information")

    def _on_WheelFeedback(self, v: dict[str, Any], now: float) -> None:
        wheel = int(v["Wheel"])  # the multiplexer: LeftCount or RightCount
        self._wheels[wheel] = (int(v["Counter"]), int(v["RightCount" if wheel else "LeftCount"]))
        left, right = self._wheels.get(0), self._wheels.get(1)
        if left is None or right is None or left[0] != right[0] or self.odometry is None:
            return  # wait for both wheels of the same cycle
        self._wheels = {}
        odo = self.odometry
        gap = self._wheel_gap(left[0], now)
        stamp = now if gap is not None else self._wheel_stamp(left[0], now)
        self._last_wheel, self._wheel_time = (now, left[0]), stamp
        if gap is not None:
            # counts after a gap may come from restarted counters: a new baseline, no motion
            self.stats["odometry_rebaselined"] += 1
            log.info("wheel odometry re-baselined: %s", gap)
            if not self._odom_gap:  # else held already, when the gap began
                self._hold_odometry(0.0)
            odo.hold()
            odo.update(left[1], right[1], stamp)
            self._odom_gap = self.state == LinkState.LOST
            return
        if not odo.update(left[1], right[1], stamp):
            return
        # The EKF weighs the wheels with its own model of their errors (EkfNoise.wheel_*):
        # radius and track errors and slip, which /odom_raw's quantisation-based twist
        # covariance does not contain; with that one the wheels would outvote the gyro.
        self.ekf.update_wheels(odo.linear, odo.angular, stamp=stamp)
        self._notify("odometry")

    def _on_ImuGyro(self, v: dict[str, Any], now: float) -> None:
        gyro = (float(v["X"]), float(v["Y"]), float(v["Z"]))
        accel = self.imu[1] if self.imu is not None else (0.0, 0.0, 0.0)
        self.imu = (gyro, accel)
        self.imu_stamp = now
        if self.odometry is not None and not self.status_code & _IMU_FAULT and \
                not self._odom_gap:
            # the gyro is the EKF's yaw-rate reference; once the lower computer flags the
            # IMU as faulty (frozen output) the EKF runs on the wheels alone. The samples
            # are queued and fused as one with the next wheel update (one EKF step per cycle)
            self.ekf.add_gyro(gyro[2], now, sigma=self.config.gyro_sigma)

    def _on_ImuAccel(self, v: dict[str, Any], now: float) -> None:
        gyro = self.imu[0] if self.imu is not None else (0.0, 0.0, 0.0)
        self.imu = (gyro, (float(v["X"]), float(v["Y"]), float(v["Z"])))
        self.imu_stamp = now
        self._notify("imu")

    def _on_MotionState(self, v: dict[str, Any], now: float) -> None:
        self.measured_twist = (float(v["Linear"]), float(v["Angular"]))
        self._notify("twist")

    def _on_Odometer(self, v: dict[str, Any], now: float) -> None:
        self.odometer = float(v["Distance"])
        self._notify("odometer")

    def _on_StatusCode(self, v: dict[str, Any], now: float) -> None:
        self.status_code = int(v["Code"])
        if self.status_code & _IMU_FAULT:
            self.ekf.discard_gyro()  # queued samples of a gyro now known to be frozen
        self._notify("status_code")

    def _on_SystemStatus(self, v: dict[str, Any], now: float) -> None:
        previous = self.system_status.get("RobotState")
        self.system_status = v
        self._control_can = v["ControlMode"] in (1, "Can")
        # enabled: done; e-stopped or faulted: standby after that is the operator's decision
        if self._control_can or v["RobotState"] in _ESTOP_OR_FAULT:
            self._enable_wanted = False
        if previous is not None and previous != v["RobotState"]:
            self._notify("system_status")
        if self.state not in (LinkState.LOST, LinkState.WAITING):  # a Heartbeat comes first
            self._settle()

    def _on_LedState(self, v: dict[str, Any], now: float) -> None:
        self.leds[(int(v["Strip"]), int(v["Submodule"]))] = {
            k: int(v[k]) for k in ("Urgency", "Abnormal", "Normal", "Color")}

    def _bms(self, name: str, v: dict[str, Any], now: float) -> None:
        if self.bms.update(name, v):
            self._notify("battery")

    def _on_BmsPack(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsPack", v, now)

    def _on_BmsCell(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsCell", v, now)

    def _on_BmsCapacity(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsCapacity", v, now)

    def _on_BmsStatus(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsStatus", v, now)

    def _on_BmsLife(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsLife", v, now)

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


def _continues(last: tuple[float, float], uptime: float, now: float,
               slack: float = UPTIME_SLACK) -> bool:
    """Whether a Heartbeat's ``uptime`` received at ``now`` continues the timeline ``last``:
    never backwards (a frame handled late is still in order; a restart starts again near 0),
    and within ``slack`` (+ 2 % of the gap) of what the receiver's clock expects."""
    expected = last[0] + (now - last[1])
    return uptime > last[0] and abs(uptime - expected) <= slack + 0.02 * (now - last[1])
