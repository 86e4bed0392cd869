"""The compiled codec against cantools, the independent implementation of the same DBC."""

from __future__ import annotations

import contextlib
import math
import subprocess
import sys

import cantools
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lowerbase.errors import (
    EncodeError,
    FrameLengthError,
    LowerbaseError,
    SignalRangeError,
    UnknownMessageError,
)
from lowerbase.protocol.codec import DBC_PATH, MessageCodec, SignalSpec, default_codec

CODEC = default_codec()
DB = cantools.database.load_file(str(DBC_PATH))
NAMES = [m.name for m in CODEC]

CONTRACT = {
    "MotionCommand", "LedCommand", "ControlCommand", "ParameterRequest", "VersionRequest",
    "WheelFeedback", "MotionState", "Odometer", "ImuGyro", "ImuAccel", "SystemStatus",
    "StatusCode", "LedState", "ParameterResponse", "VersionResponse", "Heartbeat",
}


def physical(msg: MessageCodec, spec: SignalSpec, raw: int) -> int | float:
    """What cantools makes of a raw value (the reference arithmetic)."""
    sig = DB.get_message_by_name(msg.name).get_signal_by_name(spec.name)
    return sig.conversion.raw_to_scaled(raw, decode_choices=False)  # type: ignore[no-any-return]


def signal_values(msg: MessageCodec) -> st.SearchStrategy[dict[str, int | float]]:
    fields = {}
    for s in msg.signals:
        if s.is_float:
            fields[s.name] = st.floats(
                min_value=s.minimum, max_value=s.maximum, width=32, allow_nan=False
            )
        else:
            fields[s.name] = st.integers(s.raw_min, s.raw_max).map(
                lambda raw, s=s: physical(msg, s, raw)
            )
    return st.fixed_dictionaries(fields)


def test_catalog_has_every_contract_message_and_bms_frames() -> None:
    names = set(NAMES)
    assert names >= CONTRACT
    bms = {n for n in names if n.startswith("Bms")}
    assert len(bms) >= 4
    out = subprocess.run(
        [sys.executable, "-m", "cantools", "dump", str(DBC_PATH)],
        capture_output=True, text=True, check=True,
    ).stdout
    for name in CONTRACT | bms:
        assert f"Name:           {name}" in out


def test_every_signal_is_documented_and_periodic_frames_count() -> None:
    for msg in CODEC:
        assert msg.comment, msg.name
        for s in msg.signals:
            assert s.comment, f"{msg.name}.{s.name}"
            assert s.minimum is not None and s.maximum is not None
        if msg.is_periodic and msg.name != "StatusCode":
            assert msg.has_counter, msg.name
        assert msg.length <= 8
    ids = sorted(m.frame_id for m in CODEC)
    commands = [CODEC.message(n).frame_id for n in ("ControlCommand", "MotionCommand")]
    assert commands == ids[:2]  # the highest CAN priority is safety and commands


@pytest.mark.parametrize("name", NAMES)
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_encode_decode_equal_cantools(name: str, data: st.DataObject) -> None:
    msg = CODEC.message(name)
    ref = DB.get_message_by_name(name)
    values = data.draw(signal_values(msg))
    ours = msg.encode(values)
    assert ours == ref.encode(values, strict=True)
    assert msg.decode(ours) == ref.decode(ours, decode_choices=False)
    named = {k: (str(v) if not isinstance(v, (int, float)) else v)
             for k, v in ref.decode(ours, decode_choices=True).items()}
    assert msg.decode(ours, decode_choices=True) == named


@pytest.mark.parametrize("name", NAMES)
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_random_payloads_decode_like_cantools_or_raise_typed(
    name: str, data: st.DataObject
) -> None:
    msg = CODEC.message(name)
    ref = DB.get_message_by_name(name)
    payload = data.draw(st.binary(min_size=msg.length, max_size=msg.length))
    expected = ref.decode(payload, decode_choices=False)
    loose = msg.decode(payload, strict=False)
    # repr: NaN float signals compare unequal to themselves
    assert repr(CODEC.decoders()[msg.frame_id](payload, False)) == repr((name, loose))
    assert loose.keys() == expected.keys()
    for key, value in expected.items():
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(loose[key])
        else:
            assert loose[key] == value
    try:
        strict = msg.decode(payload)
    except SignalRangeError:
        out_of_range = [
            s for s in msg.signals
            if not (s.minimum <= expected[s.name] <= s.maximum)  # type: ignore[operator]
        ]
        assert out_of_range
    else:
        assert strict == loose


@settings(max_examples=300, deadline=None)
@given(frame_id=st.integers(0, 0x7FF), payload=st.binary(max_size=8))
def test_fuzz_frames_only_typed_errors(frame_id: int, payload: bytes) -> None:
    with contextlib.suppress(LowerbaseError):
        CODEC.decode(frame_id, payload)


def test_typed_errors() -> None:
    with pytest.raises(UnknownMessageError):
        CODEC.decode(0x7FF, b"")
    with pytest.raises(UnknownMessageError):
        CODEC.message("NoSuchMessage")
    with pytest.raises(FrameLengthError):
        CODEC.decode(CODEC.message("MotionCommand").frame_id, b"\x00" * 5)
    mc = CODEC.message("MotionCommand")
    good = {"Linear": 0.5, "Angular": 0.0, "Mode": "Raw", "Counter": 0}
    for bad in (math.nan, math.inf, -math.inf, 3.5):
        with pytest.raises(SignalRangeError):
            mc.encode({**good, "Linear": bad})
    with pytest.raises(EncodeError, match="missing"):
        mc.encode({"Linear": 0.5})
    with pytest.raises(EncodeError, match="unknown"):
        mc.encode({**good, "Speed": 1})
    with pytest.raises(EncodeError, match="choice"):
        mc.encode({**good, "Mode": "Turbo"})
    with pytest.raises(EncodeError):
        mc.encode({**good, "Linear": "fast"})
    raw_out_of_range = (4000).to_bytes(2, "little", signed=True) + bytes(4)
    with pytest.raises(SignalRangeError, match="Linear"):
        mc.decode(raw_out_of_range)
    assert mc.decode(raw_out_of_range, strict=False)["Linear"] == pytest.approx(4.0)


def test_counter_and_choices_round_trip() -> None:
    wf = CODEC.message("WheelFeedback")
    values = {"Count": -(2**31), "Velocity": -1.234, "Current": 31.75, "Wheel": "Right",
              "DriverStatus": 5, "Counter": 15}
    decoded = wf.decode(wf.encode(values), decode_choices=True)
    assert decoded == {**values, "Velocity": pytest.approx(-1.234)}
