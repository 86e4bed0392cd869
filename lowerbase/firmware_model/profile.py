"""The robot profile: validated, frozen dataclasses loaded from a TOML file the user can copy.

Every numeric field declares its unit and allowed range next to its default (``_num``); the
same table validates a profile file, a dataclass built in code (``__post_init__``) and a
parameter written over the wire (:meth:`ChassisParams.with_wire_value`). Any violation is a
:class:`~lowerbase.errors.ConfigError` with one line naming the file, ``section.key``, the bad
value and the allowed range. Missing keys and sections take the defaults below, which equal
``lowerbase/profiles/default.toml``; unknown keys and sections are rejected.

Change a loaded profile with :func:`dataclasses.replace` (it re-validates), e.g.
``replace(p, chassis=replace(p.chassis, max_linear=0.8))``, or :meth:`Profile.replace`.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields, replace
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

from lowerbase.errors import ConfigError
from lowerbase.files import read_toml
from lowerbase.firmware_model.allan import STANDARD_GRAVITY, check_instabilities


def _num(default: float, lo: float, hi: float, unit: str = "", *, integer: bool = False) -> Any:
    """A numeric field with its default, inclusive range [lo, hi] and unit."""
    meta = {"range": (lo, hi), "unit": unit, "integer": integer}
    return field(default=default, metadata=meta)


def _text(default: str, max_len: int = 64) -> Any:
    """A printable-ASCII string field of 1..max_len characters."""
    return field(default=default, metadata={"max_len": max_len})


def _fmt(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


class _Validated:
    """Mixin: checks and normalises every field from its metadata after ``__init__``."""

    SECTION: ClassVar[str] = ""

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            where = f"{self.SECTION}.{f.name}"
            if "range" in f.metadata:
                object.__setattr__(self, f.name, _check_number(where, value, f.metadata))
            elif "max_len" in f.metadata:
                _check_text(where, value, f.metadata["max_len"])
            elif f.type in ("bool", bool) and not isinstance(value, bool):
                raise ConfigError(f"{where} = {value!r} must be true or false")
        self._check_relations()

    def _check_relations(self) -> None:
        """Cross-field checks; overridden where fields constrain each other."""


def _check_number(where: str, value: object, meta: Mapping[str, Any]) -> float | int:
    lo, hi = meta["range"]
    unit = f" {meta['unit']}" if meta["unit"] else ""
    kind = "an integer" if meta["integer"] else "a number"
    allowed = f"{kind} in {_fmt(lo)}..{_fmt(hi)}{unit}"
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where} = {value!r} is not {kind}; allowed: {allowed}")
    if meta["integer"]:
        if isinstance(value, float):
            if not value.is_integer():
                raise ConfigError(f"{where} = {value!r} is not {kind}; allowed: {allowed}")
            value = int(value)
    else:
        value = float(value)
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ConfigError(f"{where} = {_fmt(value)} is out of range; allowed: {allowed}")
    return value


def _check_text(where: str, value: object, max_len: int) -> None:
    ok = isinstance(value, str) and 0 < len(value) <= max_len
    if not ok or not str(value).isascii() or not str(value).isprintable():
        raise ConfigError(
            f"{where} = {value!r} is invalid; allowed: 1..{max_len} printable ASCII characters"
        )


@dataclass(frozen=True)
class IdentityParams(_Validated):
    """Version strings answered to VersionRequest (woosh_msgs version topics)."""

    SECTION: ClassVar[str] = "identity"
    hardware_version: str = _text("LB-AMR-HW-1.0")  # HardwareVersion, printable ASCII
    software_version: str = _text("lowerbase-fw-0.1.0")  # SoftwareVersion
    iap_software_version: str = _text("lowerbase-iap-0.1.0")  # IapSoftwareVersion (bootloader)
    movebase_type: str = _text("lowerbase-dd-0806")  # MovebaseType


# woosh Parameter names (the ParameterRequest.Index value table, in index order) -> field names.
CHASSIS_WIRE_NAMES: Mapping[str, str] = MappingProxyType(
    {
        "wheelPerimeter": "wheel_perimeter",
        "wheelDistant": "wheel_distant",
        "ratioLeft": "ratio_left",
        "ratioRight": "ratio_right",
        "pulsePerCircle": "pulse_per_circle",
        "maxRPM": "max_rpm",
        "minSpeed": "min_speed",
        "maxSpeed": "max_speed",
        "maxLinear": "max_linear",
        "maxAngular": "max_angular",
        "joystickMaxLinear": "joystick_max_linear",
        "joystickMaxAngular": "joystick_max_angular",
        "commandTimeout": "command_timeout",
        "linearAccelLimit": "linear_accel_limit",
        "linearDecelLimit": "linear_decel_limit",
        "angularAccelLimit": "angular_accel_limit",
        "angularDecelLimit": "angular_decel_limit",
    }
)


@dataclass(frozen=True)
class ChassisParams(_Validated):
    """The lower computer's parameters (woosh_msgs/Parameter plus the safety/smoother limits).

    Ranges keep every value inside the ParameterRequest.Value wire range (|v| <= 1e6) and the
    speed limits inside MotionCommand's (|v| <= 3 m/s, |w| <= 6 rad/s).
    """

    SECTION: ClassVar[str] = "chassis"
    wheel_perimeter: float = _num(0.6283, 0.05, 10.0, "m")  # wheel circumference (0.20 m dia)
    wheel_distant: float = _num(0.50, 0.05, 10.0, "m")  # track: distance between wheel contacts
    ratio_left: float = _num(20.0, 0.1, 1000.0)  # gear reduction motor:wheel, left
    ratio_right: float = _num(20.0, 0.1, 1000.0)  # gear reduction motor:wheel, right
    pulse_per_circle: int = _num(10000, 1, 1_000_000, "pulses", integer=True)  # per MOTOR rev
    max_rpm: float = _num(3000.0, 1.0, 100_000.0, "rpm")  # motor speed limit
    min_speed: float = _num(0.005, 0.0, 1.0, "m/s")  # rim speeds below this do not move a wheel
    max_speed: float = _num(1.5, 0.01, 10.0, "m/s")  # hard rim-speed limit of either wheel
    max_linear: float = _num(1.2, 0.01, 3.0, "m/s")  # |v| limit of the base
    max_angular: float = _num(1.0, 0.01, 6.0, "rad/s")  # |w| limit of the base
    joystick_max_linear: float = _num(0.6, 0.0, 3.0, "m/s")  # |v| limit in remote control
    joystick_max_angular: float = _num(0.8, 0.0, 6.0, "rad/s")  # |w| limit in remote control
    command_timeout: float = _num(0.5, 0.02, 10.0, "s")  # brake if no MotionCommand this long
    linear_accel_limit: float = _num(0.8, 0.01, 20.0, "m/s^2")  # smoother, |v| increasing
    linear_decel_limit: float = _num(1.0, 0.01, 20.0, "m/s^2")  # smoother, |v| decreasing
    angular_accel_limit: float = _num(1.5, 0.01, 50.0, "rad/s^2")  # smoother, |w| increasing
    angular_decel_limit: float = _num(2.0, 0.01, 50.0, "rad/s^2")  # smoother, |w| decreasing

    def _check_relations(self) -> None:
        if self.min_speed >= self.max_speed:
            raise ConfigError(
                f"chassis.min_speed = {_fmt(self.min_speed)} must be below "
                f"chassis.max_speed = {_fmt(self.max_speed)} m/s"
            )

    @property
    def wheel_radius(self) -> float:
        """Nominal wheel radius [m] = wheel_perimeter / 2pi."""
        return self.wheel_perimeter / (2.0 * math.pi)

    def as_wire_dict(self) -> dict[str, float]:
        """Values keyed by woosh/DBC name (wheelPerimeter, ...), in ParameterRequest index order."""
        return {wire: getattr(self, name) for wire, name in CHASSIS_WIRE_NAMES.items()}

    def with_wire_value(self, wire_name: str, value: float) -> ChassisParams:
        """A copy with one parameter set by its wire name; ConfigError if unknown or invalid."""
        name = CHASSIS_WIRE_NAMES.get(wire_name)
        if name is None:
            raise ConfigError(f"unknown chassis parameter {wire_name!r}")
        changes: dict[str, Any] = {name: value}
        return replace(self, **changes)

    @classmethod
    def from_wire_dict(
        cls, values: Mapping[str, float], base: ChassisParams | None = None
    ) -> ChassisParams:
        """``base`` (default: the defaults) with the given wire-named values applied at once."""
        unknown = sorted(set(values) - set(CHASSIS_WIRE_NAMES))
        if unknown:
            raise ConfigError(f"unknown chassis parameter(s): {', '.join(unknown)}")
        kwargs: dict[str, Any] = {CHASSIS_WIRE_NAMES[k]: v for k, v in values.items()}
        return replace(base if base is not None else cls(), **kwargs)


@dataclass(frozen=True)
class MotorParams(_Validated):
    """Motor + servo driver of one wheel (both wheels use the same)."""

    SECTION: ClassVar[str] = "motor"
    time_constant: float = _num(0.05, 0.0, 1.0, "s")  # velocity-loop first-order lag (0 = none)
    max_wheel_accel: float = _num(3.0, 0.0, 50.0, "m/s^2")  # driver ramp at the rim (0 = none)
    robot_mass: float = _num(150.0, 1.0, 5000.0, "kg")  # total, each wheel carries half
    rolling_resistance: float = _num(0.015, 0.0, 0.5)  # coefficient Crr (Coulomb friction)
    viscous_friction: float = _num(5.0, 0.0, 1000.0, "N*s/m")  # per wheel, at the rim
    torque_constant: float = _num(0.15, 0.001, 10.0, "N*m/A")  # motor side
    gear_efficiency: float = _num(0.9, 0.1, 1.0)  # gearbox efficiency, each direction
    idle_current: float = _num(0.3, 0.0, 10.0, "A")  # driver/motor current at zero torque
    over_current_limit: float = _num(20.0, 0.1, 31.75, "A")  # |current| above this ...
    over_current_time: float = _num(0.5, 0.0, 10.0, "s")  # ... this long latches over-current
    stall_current: float = _num(25.0, 0.0, 100.0, "A")  # current of a blocked, commanded motor
    stall_speed: float = _num(0.01, 0.0, 1.0, "m/s")  # setpoints below this never count as stall
    stall_time: float = _num(0.3, 0.0, 10.0, "s")  # wheel under half its setpoint this long
    # tyre-floor friction coefficient mu: a wheel pressing the robot against something the world
    # refuses holds while its rim force is under mu * (robot_mass / 2) * g, else it slips
    # (physical-data.md 3.2: traction mu 0.5-0.7 for AMR drive wheels on concrete)
    traction: float = _num(0.6, 0.0, 2.0)


@dataclass(frozen=True)
class ImuParams(_Validated):
    """6-axis MEMS IMU at the base centre, axes = base frame. Defaults: ICM-42688-P-like."""

    SECTION: ClassVar[str] = "imu"
    rate_hz: float = _num(100.0, 1.0, 10_000.0, "Hz")  # output data rate (noise bandwidth)
    gyro_noise_density: float = _num(0.0028, 0.0, 1.0, "deg/s/sqrt(Hz)")  # white (ARW)
    accel_noise_density: float = _num(70.0, 0.0, 10_000.0, "ug/sqrt(Hz)")  # white (VRW)
    gyro_random_walk: float = _num(5e-7, 0.0, 1e-2, "rad/s^2/sqrt(Hz)")  # Kalibr bias walk
    accel_random_walk: float = _num(1e-5, 0.0, 1.0, "m/s^3/sqrt(Hz)")  # Kalibr bias walk
    gyro_bias_instability: float = _num(3.0, 0.0, 1000.0, "deg/h")  # Allan minimum / 0.664
    accel_bias_instability: float = _num(50.0, 0.0, 10_000.0, "ug")  # Allan minimum / 0.664
    bias_walk_bound: float = _num(3.0, 0.1, 100.0)  # walk reflects at +-this x its 1 h sigma
    gyro_turn_on_bias: float = _num(0.5, 0.0, 30.0, "deg/s")  # sigma per axis, drawn at boot
    accel_turn_on_bias: float = _num(20.0, 0.0, 200.0, "mg")  # sigma per axis, drawn at boot
    gyro_scale_error: float = _num(0.003, -0.1, 0.1)  # output = (1 + e) * true
    accel_scale_error: float = _num(0.005, -0.1, 0.1)  # output = (1 + e) * true
    gyro_full_scale: float = _num(2000.0, 15.0, 4000.0, "deg/s")  # saturation
    accel_full_scale: float = _num(16.0, 2.0, 40.0, "g")  # saturation
    gravity: float = _num(STANDARD_GRAVITY, 9.7, 9.9, "m/s^2")  # local g, added on +z
    seed: int = _num(42, 0, 2**63 - 1, integer=True)  # noise generator seed
    noise: bool = True  # false: an ideal sensor (no noise, bias, walk or scale error)

    def _check_relations(self) -> None:
        """The bias instabilities must lie above the Allan floor of white noise + walk."""
        check_instabilities(self)


@dataclass(frozen=True)
class RatesParams(_Validated):
    """Rates the catalog does not fix (frame cycle times come from the DBC)."""

    SECTION: ClassVar[str] = "rates"
    control_hz: int = _num(200, 100, 1000, "Hz", integer=True)  # MCU control loop

    def _check_relations(self) -> None:
        if self.control_hz not in (100, 200, 500, 1000):
            raise ConfigError(
                f"rates.control_hz = {self.control_hz} is invalid; allowed: 100, 200, 500 or "
                "1000 Hz (the period must divide the 10 ms IMU frame cycle)"
            )


@dataclass(frozen=True)
class TruthParams(_Validated):
    """How the emulated robot differs from its parameters (UMBmark E_d, E_b) and slips."""

    SECTION: ClassVar[str] = "truth"
    left_radius_error: float = _num(0.0, -0.2, 0.2)  # true radius = nominal * (1 + e)
    right_radius_error: float = _num(0.003, -0.2, 0.2)  # true radius = nominal * (1 + e)
    track_error: float = _num(0.01, -0.2, 0.2)  # true track = wheel_distant * (1 + e)
    slip_rate_per_km: float = _num(0.0, 0.0, 10_000.0, "1/km")  # random slip events (0 = none)
    slip_duration: float = _num(0.2, 0.001, 10.0, "s")  # length of one random event
    slip_fraction: float = _num(0.5, 0.0, 1.0)  # ground = (1 - s) * rim during an event
    accel_slip_threshold: float = _num(0.0, 0.0, 100.0, "m/s^2")  # rim accel above it slips (0=off)
    accel_slip_fraction: float = _num(0.03, 0.0, 1.0)  # slip fraction while above threshold
    seed: int = _num(7, 0, 2**63 - 1, integer=True)  # slip generator seed


@dataclass(frozen=True)
class PowerParams(_Validated):
    """The lower computer's own reading of the BMS (the BMS's protections are in [battery])."""

    SECTION: ClassVar[str] = "power"
    low_battery_soc: float = _num(20.0, 0.0, 100.0, "%")  # LOW_BATTERY below this SOC
    critical_battery_soc: float = _num(5.0, 0.0, 100.0, "%")  # CRITICAL_BATTERY below this
    battery_temp_warning: float = _num(50.0, -40.0, 120.0, "degC")  # BATTERY_OVER_TEMPERATURE

    def _check_relations(self) -> None:
        if self.critical_battery_soc > self.low_battery_soc:
            raise ConfigError(
                f"power.critical_battery_soc = {_fmt(self.critical_battery_soc)} must not be "
                f"above power.low_battery_soc = {_fmt(self.low_battery_soc)} %"
            )


SECTIONS: Mapping[str, type[_Validated]] = MappingProxyType(
    {
        "identity": IdentityParams,
        "chassis": ChassisParams,
        "motor": MotorParams,
        "imu": ImuParams,
        "rates": RatesParams,
        "truth": TruthParams,
        "power": PowerParams,
    }
)


@dataclass(frozen=True)
class Profile:
    """One robot: every section validated; ``battery`` is left to lowerbase.bms to parse."""

    identity: IdentityParams = field(default_factory=IdentityParams)
    chassis: ChassisParams = field(default_factory=ChassisParams)
    motor: MotorParams = field(default_factory=MotorParams)
    imu: ImuParams = field(default_factory=ImuParams)
    rates: RatesParams = field(default_factory=RatesParams)
    truth: TruthParams = field(default_factory=TruthParams)
    power: PowerParams = field(default_factory=PowerParams)
    battery: Mapping[str, Any] = field(default_factory=dict, hash=False)  # opaque [battery]
    source: str = field(default="<defaults>", compare=False)  # file it was loaded from

    def replace(self, **changes: Any) -> Profile:
        """A copy with whole sections replaced (same as :func:`dataclasses.replace`)."""
        return replace(self, **changes)


def default_profile_path() -> Path:
    """Path of the packaged default profile (lowerbase/profiles/default.toml)."""
    return Path(str(resources.files("lowerbase") / "profiles" / "default.toml"))


def load_profile(path: str | Path | None = None) -> Profile:
    """Load and validate a profile TOML file (None = the packaged default)."""
    p = Path(path) if path is not None else default_profile_path()
    return profile_from_dict(read_toml(p, "profile"), source=str(p))


def profile_from_dict(data: Mapping[str, Any], source: str = "<dict>") -> Profile:
    """Build a Profile from parsed TOML; ConfigError messages start with ``source``."""
    try:
        # [sensors] is parsed and validated by lowerbase.world.sensors, not here
        sections, battery = build_sections(data, SECTIONS, ignored=("sensors",))
        return Profile(**sections, battery=battery, source=source)
    except ConfigError as e:
        raise ConfigError(f"{source}: {e}") from None


def build_sections(data: Mapping[str, Any], classes: Mapping[str, type[_Validated]],
                   ignored: tuple[str, ...] = ()) -> tuple[dict[str, Any], dict[str, Any]]:
    """The validated section objects of a profile's tables (``classes``: table name -> section
    dataclass) and its opaque [battery] table; unknown tables and keys are refused with a
    did-you-mean, tables in ``ignored`` are left to their own parser."""
    _reject_unknown(data, [*classes, "battery", *ignored], "section", "")
    sections: dict[str, Any] = {}
    for name, cls in classes.items():
        table = data.get(name, {})
        if not isinstance(table, Mapping):
            raise ConfigError(f"[{name}] must be a table, not {table!r}")
        _reject_unknown(table, [f.name for f in fields(cls)], "key", f"{name}.")  # type: ignore[arg-type]
        sections[name] = cls(**table)
    battery = data.get("battery", {})
    if not isinstance(battery, Mapping):
        raise ConfigError(f"[battery] must be a table, not {battery!r}")
    return sections, dict(battery)


def _reject_unknown(table: Mapping[str, Any], known: list[str], what: str, prefix: str) -> None:
    for key in table:
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1)
            hint = f"did you mean {prefix}{close[0]}?" if close else f"known: {', '.join(known)}"
            raise ConfigError(f"unknown {what} {prefix}{key}; {hint}")


def field_defaults(cls: type[_Validated]) -> dict[str, Any]:
    """The default value of every field of a section class (used to check default.toml)."""
    return {f.name: f.default for f in fields(cls) if f.default is not MISSING}  # type: ignore[arg-type]
