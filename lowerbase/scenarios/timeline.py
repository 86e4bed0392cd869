"""A wheeled scenario's timeline: the initial state and the actions (what the upper computer
or the world does at a time), with the wire's value tables they use."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

from lowerbase.firmware_model.faults import Fault

#: RobotState value table of SystemStatus (chassis.dbc)
ROBOT_STATES = ("Boot", "Standby", "Active", "EmergencyStop", "Fault")
#: DriverCore LinkState values
LINK_STATES = ("waiting", "configuring", "ready", "lost", "standby")
#: ControlCommand actions: scenario action name -> ControlCommand value name
CONTROL_ACTIONS = {
    "enable": "EnableCanControl",
    "standby": "Standby",
    "estop": "EStopSet",
    "estop_release": "EStopRelease",
    "fault_clear": "FaultClear",
    "odometer_reset": "OdometerReset",
    "reboot": "Reboot",
}
#: actions that reach into the emulated lower computer, not through the wire
IN_PROCESS_ONLY = ("charger", "slip", "clear_fault")
TWIST_PERIOD = 0.05  #: [s] twists are published at 20 Hz during a segment, as a nav stack does


# -- the model ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Pose:
    x: float = 0.0  #: [m]
    y: float = 0.0  #: [m]
    yaw: float = 0.0  #: [rad]

    @property
    def is_origin(self) -> bool:
        return self.x == 0.0 and self.y == 0.0 and self.yaw == 0.0


@dataclass(frozen=True)
class Initial:
    soc: float = 80.0  #: [%] 0..100, state of charge of the pack at power-on
    pose: Pose = field(default_factory=Pose)  #: true pose at power-on (odometry starts there)
    charger: bool = False  #: charger connected at power-on


@dataclass(frozen=True)
class Action:
    """Something that happens at ``at`` [s]. Subclasses carry the kind's arguments."""

    at: float
    kind: ClassVar[str] = ""

    def label(self) -> str:
        """Short text for plots and logs."""
        return self.kind

    @property
    def end(self) -> float:
        """[s] when the action's effect ends (= ``at`` for instantaneous ones)."""
        return self.at


@dataclass(frozen=True)
class Twist(Action):
    """Publish (linear [m/s], angular [rad/s]) at 20 Hz for ``duration`` [s]."""

    linear: float = 0.0
    angular: float = 0.0
    duration: float = 1.0
    smoothed: bool = False  #: True: /smooth_cmd_vel (Mode Smoothed), False: /base_cmd_vel (Raw)
    stop: bool = True  #: publish one zero twist at the end (a nav stack reaching its goal)
    kind: ClassVar[str] = "twist"

    def label(self) -> str:
        return f"twist {self.linear:g} m/s {self.angular:g} rad/s"

    @property
    def end(self) -> float:
        return self.at + self.duration


@dataclass(frozen=True)
class Led(Action):
    strip: int = 0  #: 0 body (rgbled), 1 shelf (rgbled_shelf)
    submodule: int = 0  #: 0 all, 1..8 one
    urgency: int = 0
    abnormal: int = 0
    normal: int = 0xA3  #: LedCommand Normal value (0xA3 Idle)
    color: int = 0xFFFFFF
    kind: ClassVar[str] = "led"

    def label(self) -> str:
        return f"LED #{self.color:06X}"


@dataclass(frozen=True)
class ParamWrite(Action):
    name: str = ""  #: woosh parameter name (commandTimeout, maxLinear, ...)
    value: float = 0.0
    kind: ClassVar[str] = "param"

    def label(self) -> str:
        return f"{self.name}={self.value:g}"


@dataclass(frozen=True)
class Control(Action):
    """A ControlCommand (enable, standby, estop, estop_release, fault_clear, ...)."""

    command: str = "EnableCanControl"  #: ControlCommand value name
    name: str = "enable"  #: the scenario's action name
    kind: ClassVar[str] = "control"

    def label(self) -> str:
        return self.name


@dataclass(frozen=True)
class Charger(Action):
    connected: bool = True
    kind: ClassVar[str] = "charger"

    def label(self) -> str:
        return "charger on" if self.connected else "charger off"


@dataclass(frozen=True)
class Unplug(Action):
    """Frames from the upper computer stop reaching the lower one for ``duration`` [s]."""

    duration: float = 1.0
    kind: ClassVar[str] = "unplug"

    @property
    def end(self) -> float:
        return self.at + self.duration


@dataclass(frozen=True)
class Slip(Action):
    """A wheel slips: ground speed = (1 - fraction) x rim speed for ``duration`` [s]."""

    wheel: str = "left"  #: left, right or both
    fraction: float = 0.5
    duration: float = 1.0
    kind: ClassVar[str] = "slip"

    def label(self) -> str:
        return f"slip {self.wheel} {self.fraction:g}"

    @property
    def end(self) -> float:
        return self.at + self.duration


@dataclass(frozen=True)
class FaultAt(Action):
    """Inject ``fault`` (its ``start`` unused) at ``at`` for its duration (None: to the end)."""

    fault: Fault = field(default_factory=lambda: Fault("silence"))
    kind: ClassVar[str] = "fault"

    def label(self) -> str:
        return str(self.fault)

    @property
    def end(self) -> float:
        return self.at + (self.fault.duration if self.fault.duration is not None else math.inf)

    def spec_from_boot(self) -> str:
        """The fault as ``lowerbase emulate --fault`` takes it (times from boot)."""
        return str(Fault(self.fault.kind, self.fault.arg, self.at or 1e-3, self.fault.duration))


@dataclass(frozen=True)
class ClearFault(Action):
    fault_kind: str | None = None  #: None: every injected fault
    kind: ClassVar[str] = "clear_fault"

    def label(self) -> str:
        return f"clear {self.fault_kind or 'faults'}"
