"""The legged robot's bus layout on top of ``legged.dbc``: joints, buses, CAN IDs, the MIT
special frames, locomotion states and fault bits.

The catalog describes every frame a DBC can express. The MIT protocol's three special commands
(enter motor mode, exit motor mode, set zero position) are magic 8-byte payloads on an
actuator's command ID, which no DBC signal can express: receivers test for them with
:func:`parse_special` before decoding, exactly as the actuator firmware does. A command whose
payload happens to equal a special frame (every field at its maximum, torque in its top four
raw values) is read as the special frame, as on the real actuator.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum, IntFlag
from functools import cache
from pathlib import Path

import numpy as np

from lowerbase.protocol.codec import Codec
from lowerbase.protocol.frame_table import layout

LEGGED_DBC_PATH = Path(__file__).resolve().with_name("legged.dbc")

#: legs in bus order: bus k carries leg LEGS[k]
LEGS: tuple[str, ...] = ("FR", "FL", "RR", "RL")
#: joints of a leg in CAN-ID order (ID = index + 1)
JOINTS: tuple[str, ...] = ("hip", "thigh", "calf")
#: the 12 actuator names as robot_state.actuator_states names them, joint index order
JOINT_NAMES: tuple[str, ...] = tuple(f"{leg}_{j}" for leg in LEGS for j in JOINTS)
#: CAN ID of each joint's actuator on its leg bus
MOTOR_IDS: dict[str, int] = {"hip": 1, "thigh": 2, "calf": 3}
#: command message per actuator CAN ID
COMMAND_MESSAGES: dict[int, str] = {1: "HipCommand", 2: "ThighCommand", 3: "CalfCommand"}
#: reply signal prefix per actuator CAN ID (MotorReply is multiplexed by MotorId)
REPLY_PREFIX: dict[int, str] = {1: "Hip", 2: "Thigh", 3: "Calf"}
#: the CAN ID every actuator answers on (the firmware's CAN_MASTER)
REPLY_ID = 0
#: the bus that carries the body frames (LocomotionRequest ... Bms*)
BODY_BUS = 0
N_BUSES = len(LEGS)
N_JOINTS = len(JOINT_NAMES)
#: MIT command ranges of this catalog (Ben Katz's motorcontrol defaults; T_MAX per joint)
P_MAX = 12.5
V_MAX = 65.0
KP_MAX = 500.0
KD_MAX = 5.0
T_MAX: dict[int, float] = {1: 18.0, 2: 18.0, 3: 28.0}


def joint_index(bus: int, motor_id: int) -> int:
    """Index 0..11 of the actuator with CAN ID ``motor_id`` (1..3) on leg bus ``bus`` (0..3)."""
    if not (0 <= bus < N_BUSES and 1 <= motor_id <= len(JOINTS)):
        raise ValueError(f"no actuator {motor_id} on bus {bus}")
    return bus * len(JOINTS) + motor_id - 1


def joint_address(index: int) -> tuple[int, int]:
    """(bus, CAN ID) of joint ``index`` 0..11."""
    if not 0 <= index < N_JOINTS:
        raise ValueError(f"joint index {index} is outside 0..{N_JOINTS - 1}")
    return index // len(JOINTS), index % len(JOINTS) + 1


class Special(IntEnum):
    """The MIT special commands: FF FF FF FF FF FF FF <value>."""

    ENTER_MOTOR_MODE = 0xFC
    EXIT_MOTOR_MODE = 0xFD
    ZERO_POSITION = 0xFE


_SPECIAL_PREFIX = b"\xff" * 7


def special_frame(kind: Special) -> bytes:
    """The 8-byte payload of a special command."""
    return _SPECIAL_PREFIX + bytes((int(kind),))


def parse_special(data: bytes | bytearray | memoryview) -> Special | None:
    """The special command this command payload is, or None for an ordinary command."""
    if len(data) != 8 or bytes(data[:7]) != _SPECIAL_PREFIX:
        return None
    try:
        return Special(data[7])
    except ValueError:
        return None


class LocomotionState(IntEnum):
    """robot_state.state (the seed's values 0..9)."""

    COMM_DISABLED = 0
    COMM_ENABLED = 1
    MOTOR_READY = 2
    MOTOR_COMMUTATION = 3
    MOTOR_ENABLED = 4
    IN_TEST_MODE = 5
    STANDING_MODE = 6
    IN_CONTROL = 7
    SITDOWN_MODE = 8
    MOTOR_DISABLED = 9


class RequestResult(IntEnum):
    """LocomotionStatus.RequestResult."""

    NONE = 0
    ACCEPTED = 1
    NOT_ALLOWED = 2
    FAULTED = 3
    BUSY = 4


#: LocomotionStatus.LastRequest before any request
NO_REQUEST = 15
#: LocomotionStatus.FaultJoint / no fault
NO_JOINT = 15


class Fault(IntFlag):
    """LocomotionStatus.Fault bits. Latched: a MOTOR_READY request clears them once every
    cause is gone (actuators cooled below their clear temperature, the body below
    ``thermal.body_clear_c``, the BMS's discharge switch closed and the SOC above critical);
    until then MOTOR_READY is answered Faulted (docs/legged.md)."""

    ACTUATOR_OVER_TEMPERATURE = 1 << 0
    ACTUATOR_ERROR = 1 << 1
    BATTERY_PROTECTION = 1 << 2
    BODY_OVER_TEMPERATURE = 1 << 3


class ActuatorError(IntEnum):
    """MotorReply.Error (AK-series error codes)."""

    NORMAL = 0
    MOTOR_OVER_TEMPERATURE = 1
    OVER_CURRENT = 2
    OVER_VOLTAGE = 3
    UNDER_VOLTAGE = 4
    ENCODER_FAULT = 5
    MOSFET_OVER_TEMPERATURE = 6
    MOTOR_LOCKUP = 7


@cache
def legged_codec() -> Codec:
    """The compiled codec of the packaged ``legged.dbc`` (built once per process)."""
    return Codec(LEGGED_DBC_PATH)


@dataclass(frozen=True)
class ActuatorLayouts:
    """The actuator frames' DBC layouts for the compiled packers (``frame_kernel``), stacked
    by CAN ID - 1: command m's Position, Velocity, Kp, Kd, Torque (``command_sig[m]``); reply m's
    MotorId, position, velocity, torque, Temperature, Error (``reply_sig[m]``); MotorReply's
    multiplexer alone (``mux_sig``)."""

    command_sig: np.ndarray
    command_scale: np.ndarray
    reply_sig: np.ndarray
    reply_scale: np.ndarray
    mux_sig: np.ndarray
    mux_scale: np.ndarray
    big_endian: bool


def actuator_layouts(codec: Codec) -> ActuatorLayouts:
    """:class:`ActuatorLayouts` of ``codec`` (a legged catalog); TypeError when its actuator
    frames are not all 8 bytes in one byte order."""
    ids = sorted(COMMAND_MESSAGES)
    reply = codec.message("MotorReply")
    commands = [layout(codec.message(COMMAND_MESSAGES[m]),
                       ("Position", "Velocity", "Kp", "Kd", "Torque")) for m in ids]
    replies = [layout(reply, ("MotorId", f"{p}Position", f"{p}Velocity", f"{p}Torque",
                              "Temperature", "Error")) for p in (REPLY_PREFIX[m] for m in ids)]
    mux = layout(reply, ("MotorId",))
    frames = [mux, *commands, *replies]
    if len({f.big_endian for f in frames}) != 1 or any(f.length != 8 for f in frames):
        raise TypeError(f"{LEGGED_DBC_PATH.name}: the actuator frames must be 8 bytes long in "
                        f"one byte order")
    return ActuatorLayouts(np.stack([f.sig for f in commands]),
                           np.stack([f.scale for f in commands]),
                           np.stack([f.sig for f in replies]),
                           np.stack([f.scale for f in replies]), mux.sig, mux.scale,
                           mux.big_endian)
