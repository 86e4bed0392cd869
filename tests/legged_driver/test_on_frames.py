"""LeggedDriverCore.on_frames (a period's frames at once, compiled) against on_frame frame by
frame: the same joints, state and counters, for good frames and bad ones in one batch."""

from __future__ import annotations

import numpy as np
import pytest

from lowerbase.clock import SimClock
from lowerbase.errors import ProtocolError
from lowerbase.legged_driver.core import LeggedDriverCore
from lowerbase.protocol.legged import REPLY_ID, Special, legged_codec, special_frame

CODEC = legged_codec()


def _reply(mid: int, position: float, temperature: int = 31, error: int = 0) -> bytes:
    p = {1: "Hip", 2: "Thigh", 3: "Calf"}[mid]
    return CODEC.encode("MotorReply", {"MotorId": mid, f"{p}Position": position,
                                       f"{p}Velocity": -1.5, f"{p}Torque": 2.25,
                                       "Temperature": temperature, "Error": error})


def _frames() -> list[tuple[int, int, bytes]]:
    position = CODEC.encode("BasePosition", {"X": 1.5, "Y": -2.0, "Z": 0.28, "Counter": 3})
    command = CODEC.encode("ThighCommand", {"Position": 0.3, "Velocity": 0.0, "Kp": 80.0,
                                            "Kd": 1.0, "Torque": -2.0})
    bad_mux = bytearray(_reply(1, 0.5))
    bad_mux[0] = 7  # MotorId 7: no such actuator
    return [
        (0, REPLY_ID, _reply(1, 0.25)), (2, REPLY_ID, _reply(3, -1.0, 60, 1)),
        (3, REPLY_ID, _reply(2, 2.0)), (0, 2, command), (2, 2, command),
        (1, 1, special_frame(Special.ENTER_MOTOR_MODE)),
        (0, CODEC.message("BasePosition").frame_id, position),  # for Python, in its order
        (5, REPLY_ID, _reply(1, 1.0)),  # a reply on a bus that does not exist
        (1, REPLY_ID, bytes(bad_mux)), (0, 0x7FF, bytes(8)),  # unknown ID
        (1, REPLY_ID, _reply(2, -0.75)), (0, REPLY_ID, _reply(1, 0.125)),
    ]


def test_a_batch_is_taken_as_frame_by_frame() -> None:
    frames = _frames()
    one, batch = LeggedDriverCore(lambda *a: None, SimClock()), \
        LeggedDriverCore(lambda *a: None, SimClock())
    for bus, fid, data in frames:
        one.on_frame(bus, fid, data)
    batch.on_frames(np.array([f[0] for f in frames], np.int64),
                    np.array([f[1] for f in frames], np.int64),
                    np.array([list(f[2]) for f in frames], np.uint8))
    assert batch.joints.tolist() == one.joints.tolist()
    assert batch.actuators == one.actuators
    assert dict(batch.stats) == dict(one.stats)
    assert batch.base_pos == one.base_pos == [1.5, -2.0, 0.28]
    assert dict(one.stats) == {"motor_reply": 5, "ignored": 1, "wrong_bus": 3,
                               "malformed": 2, "BasePosition": 1}
    hip = one.actuators[0]  # FR_hip: the last reply on bus 0 wins
    assert hip.position == CODEC.decode(REPLY_ID, _reply(1, 0.125))[1]["HipPosition"]
    calf = one.actuators[8]  # RR_calf
    assert (calf.temperature, calf.status) == (60.0, 1)
    assert calf.velocity == pytest.approx(-1.5, abs=0.032)  # 12 bits over +-65 rad/s


def test_arrays_of_the_wrong_shape_or_type_are_a_protocol_error() -> None:
    core = LeggedDriverCore(lambda *a: None, SimClock())
    ids, buses = np.zeros(2, np.int64), np.zeros(2, np.int64)
    for b, i, d in ((buses, ids, np.zeros((2, 4), np.uint8)),  # 4-byte payloads
                    (buses[:1], ids, np.zeros((2, 8), np.uint8)),  # buses too short
                    (buses, ids, np.zeros((2, 8), np.int64)),  # not bytes
                    (buses.astype(np.int32), ids, np.zeros((2, 8), np.uint8))):
        with pytest.raises(ProtocolError, match="on_frames takes int64"):
            core.on_frames(b, i, d)
    assert not core.stats and not core.joints.any()
