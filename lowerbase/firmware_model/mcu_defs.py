"""The emulated lower computer's constants and names (status bits as ints, states, commands,
timings), shared by :mod:`.mcu` and its parts (:mod:`.mcu_commands`, :mod:`.fastloop`,
:mod:`.mcu_frames`); :class:`McuParts` declares, for the type checker, what the parts read
of the Mcu they are mixed into. Import the public names from :mod:`.mcu` as before."""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from lowerbase.protocol.codec import MessageCodec, default_codec
from lowerbase.protocol.status_codes import LATCHED as _LATCHED
from lowerbase.protocol.status_codes import STOPPING as _STOPPING
from lowerbase.protocol.status_codes import StatusBit

if TYPE_CHECKING:  # pragma: no cover
    from collections import Counter

    import numpy as np

    from lowerbase.clock import Clock
    from lowerbase.firmware_model.encoder import EncoderCounter
    from lowerbase.firmware_model.faults import Fault
    from lowerbase.firmware_model.imu import ImuModel
    from lowerbase.firmware_model.kinematics import LimitedTwist
    from lowerbase.firmware_model.motor import WheelMotor
    from lowerbase.firmware_model.parameters import ParameterStore
    from lowerbase.firmware_model.profile import ChassisParams, Profile
    from lowerbase.firmware_model.smoother import VelocitySmoother
    from lowerbase.firmware_model.truth import GroundTruth, SlipModel
    from lowerbase.protocol.codec import Codec

#: StatusBit as plain ints: IntFlag arithmetic costs microseconds per operation, and the
#: control loop does dozens per step
SB: Any = SimpleNamespace(**{str(b.name): int(b) for b in StatusBit})
LATCHED = int(_LATCHED)
STOPPING = int(_STOPPING)

ESTOP_BITS = SB.ESTOP_BUTTON | SB.ESTOP_COMMAND
#: latched bits set by an event (not recomputed each step); FaultClear clears them
CARRIED = (
    SB.COMMAND_REJECTED | SB.PARAMETER_ERROR | SB.PARAMETER_STORE_FAILED
)

PROTOCOL_VERSION = 1
BOOT_TIME = 0.3  #: [s] from power-on to standby
BMS_POLL_PERIOD = 0.5  #: [s]
BMS_STEP = 0.1  #: [s] the pack model is stepped with the mean load over this period
#: Mcu._fault_data: the encoders' dropout (left, right), the IMU frozen, the drivers' injected
#: over-current (left, right), the wheels blocked (the stall fault; left, right)
FaultData = tuple[bool, bool, bool, bool, bool, bool, bool]
NO_FAULT_DATA: FaultData = (False,) * 7  #: with no such fault active
BMS_LINK_TIMEOUT = 3.0  #: [s] without an answer -> BMS_LINK_LOST
ENCODER_FAULT_TIME = 0.2  #: [s] commanded motion without pulses -> encoder fault
IMU_FROZEN_SAMPLES = 20  #: identical consecutive samples -> IMU fault
STANDBY_HINT_TIME = 1.0  #: [s] COMMAND_IN_STANDBY stays set after the last such command
ODOMETER_SAVE_PERIOD = 1.0  #: [s] a changed odometer is persisted this often (a crash loses less)

#: messages sent as several frames per cycle that share the cycle's counter (the catalog says)
SHARED_COUNTER = frozenset({"WheelFeedback"})
LED_DEFAULT = {"Urgency": 0, "Abnormal": 0, "Normal": 0xA3, "Color": 0xFFFFFF}  # Idle, white
VALID_LED_NORMAL = frozenset(default_codec().message("LedCommand").signal("Normal").choices)


class RobotState(enum.IntEnum):
    BOOT = 0
    STANDBY = 1
    ACTIVE = 2
    EMERGENCY_STOP = 3
    FAULT = 4


class Command(enum.IntEnum):
    ENABLE_CAN_CONTROL = 1
    STANDBY = 2
    ESTOP_SET = 3
    ESTOP_RELEASE = 4
    FAULT_CLEAR = 5
    ODOMETER_RESET = 6
    REBOOT = 7


Send = Callable[[int, bytes], None]



class McuParts:
    """The base of the Mcu's parts: nothing at run time; for the type checker, the Mcu's
    state and the methods one part calls in another."""

    if TYPE_CHECKING:  # pragma: no cover
        profile: Profile
        clock: Clock
        codec: Codec
        store: ParameterStore
        stats: Counter[str]
        faults: list[Fault]
        chassis: ChassisParams
        state: RobotState
        status: int
        motion_fault: int
        estop_command: bool
        odometer: float
        boot_counter: int
        boot_time: float
        smoother: VelocitySmoother
        truth: GroundTruth
        slip: SlipModel
        imu: ImuModel
        dt: float
        lean: bool
        leds: dict[tuple[int, int], dict[str, int]]
        imu_sample: tuple[Any, Any]
        bms: Any
        bms_snapshot: Any
        _send: Send
        _rng: np.random.Generator
        _motors: dict[str, WheelMotor]
        _encoders: dict[str, EncoderCounter]
        _enc_stuck: dict[str, float]
        _last_cmd: tuple[float, float, int] | None
        _last_cmd_time: float
        _standby_cmd_time: float
        _limited_key: tuple[float, float, ChassisParams] | None
        _limited: LimitedTwist
        _speed_limited: bool
        _watchdog: bool
        _watchdog_ramp: bool
        _repeat_of: tuple[Any, ...] | None
        _imu_due: float
        _imu_last: tuple[Any, Any] | None
        _imu_bias_applied: float
        _fault_data: FaultData
        _saved_odometer: float
        _last_save: float
        _imu_same: int
        _bms_bits: int
        _bms_charge: float
        _bms_elapsed: float
        _bms_last_answer: float
        _bms_next_poll: float
        _periodic: list[MessageCodec]
        _counters: dict[str, int]
        _due: list[float]
        _next_any_due: float
        _delayed: list[tuple[float, int, int, bytes]]
        _seq: int

        def power_on(self) -> None: ...
        def receive(self, frame_id: int, data: bytes) -> None: ...
        def step(self) -> None: ...
        def _target(self, now: float) -> tuple[float, float, bool]: ...
        def _sample_imu(self) -> None: ...
        def _poll_bms(self, now: float, silent: bool = False) -> None: ...
        def _cycle(self, name: str) -> float: ...
        def _build(self, msg: MessageCodec) -> list[dict[str, Any]]: ...
        def _save_state(self) -> None: ...
        def _active(self, kind: str, arg: str | None = None) -> Fault | None: ...
        def wheel_velocity(self, side: str) -> float: ...
        def _measured_twist(self) -> tuple[float, float]: ...
        def _emit(self, name: str, values: dict[str, Any]) -> None: ...
        def _send_out(self, frame_id: int, data: bytes) -> None: ...
        def _release_delayed(self, now: float) -> None: ...
        def _apply_faults(self) -> None: ...
        def _bms_link_lost(self) -> bool: ...


_RANGES: dict[tuple[str, str], tuple[float, float]] = {
    (m.name, s.name): (
        s.minimum if s.minimum is not None else -math.inf,
        s.maximum if s.maximum is not None else math.inf,
    )
    for m in default_codec() for s in m.signals
}


def _clip(value: float, msg: MessageCodec, signal: str) -> float:
    """Saturate a measurement at its signal's range, as a sensor register does."""
    lo, hi = _RANGES[msg.name, signal]
    return lo if value < lo else hi if value > hi else value
