"""The driver core's definitions: link states, its configuration, the Heartbeat timeline
test, the constants its frame handling uses (:mod:`lowerbase.driver.core` re-exports them)."""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass, field

from lowerbase.driver.ekf import EkfNoise
from lowerbase.driver.odometry import OdometryNoise
from lowerbase.errors import LowerbaseError
from lowerbase.protocol.status_codes import StatusBit

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


def _continues(last: tuple[float, float], uptime: float, now: float,
               slack: float = UPTIME_SLACK) -> bool:
    """Whether a Heartbeat's ``uptime`` received at ``now`` continues the timeline ``last``:
    never backwards (a frame handled late is still in order; a restart starts again near 0),
    and within ``slack`` (+ 2 % of the gap) of what the receiver's clock expects."""
    expected = last[0] + (now - last[1])
    return uptime > last[0] and abs(uptime - expected) <= slack + 0.02 * (now - last[1])
