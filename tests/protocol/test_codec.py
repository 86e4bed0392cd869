"""The compiled codec against cantools, the independent implementation of the same DBC."""

from __future__ import annotations

import contextlib
import math
import subprocess
import sys
from pathlib import Path

import cantools
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lowerbase.errors import (
    EncodeError,
    FrameLengthError,
    LowerbaseError,
    ProtocolError,
    SignalRangeError,
    UnknownMessageError,
)
from lowerbase.protocol.codec import DBC_PATH, Codec, MessageCodec, SignalSpec, default_codec

CODEC = default_codec()
DB = cantools.database.load_file(str(DBC_PATH))
NAMES = [m.name for m in CODEC]
#: (message, multiplexer value or None): every signal set a frame can carry
CASES = [(m.name, k) for m in CODEC for k in (list(m.variants) or [None])]

CONTRACT = {
    "MotionCommand", "LedCommand", "ControlCommand", "ParameterRequest", "VersionRequest",
    "WheelFeedback", "MotionState", "Odometer", "ImuGyro", "ImuAccel", "SystemStatus",
    "StatusCode", "LedState", "ParameterResponse", "VersionResponse", "Heartbeat",
}


def physical(msg: MessageCodec, spec: SignalSpec, raw: int) -> int | float:
    """What cantools makes of a raw value (the reference arithmetic)."""
    sig = DB.get_message_by_name(msg.name).get_signal_by_name(spec.name)
    return sig.conversion.raw_to_scaled(raw, decode_choices=False)  # type: ignore[no-any-return]


def signal_values(
    msg: MessageCodec, mux: int | None = None
) -> st.SearchStrategy[dict[str, int | float]]:
    fields: dict[str, st.SearchStrategy[int | float]] = {}
    for s in msg.signals if mux is None else msg.variants[mux]:
        if s.is_multiplexer:
            fields[s.name] = st.just(mux)  # type: ignore[arg-type]
            continue
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


@pytest.mark.parametrize(("name", "mux"), CASES)
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_encode_decode_equal_cantools(name: str, mux: int | None, data: st.DataObject) -> None:
    msg = CODEC.message(name)
    ref = DB.get_message_by_name(name)
    values = data.draw(signal_values(msg, mux))
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
            s for s in msg.signals if s.name in expected
            and not (s.minimum <= expected[s.name] <= s.maximum)  # type: ignore[operator]
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
    values = {"RightCount": -(2**31), "RightVelocity": -1.234, "RightCurrent": 31.75,
              "Wheel": "Right", "RightDriverStatus": 5, "Counter": 15}
    decoded = wf.decode(wf.encode(values), decode_choices=True)
    assert decoded == {**values, "RightVelocity": pytest.approx(-1.234)}


#: WheelFeedback bytes from the codec before the message was multiplexed (plain Wheel, Count,
#: Velocity, Current, DriverStatus, Counter): (wheel, count, velocity, current, status, counter)
WHEEL_FEEDBACK_WIRE = [
    (0, 0, 0.0, 0.0, 0, 0, "0000000000000000"),
    (0, 123456, 0.512, 1.25, 0, 7, "40e2010000020570"),
    (1, 123457, 0.498, -1.5, 4, 7, "41e20100f201fa79"),
    (0, -2147483648, -10.0, -32.0, 7, 15, "00000080f0d880fe"),
    (1, 2147483647, 10.0, 31.75, 5, 15, "ffffff7f10277ffb"),
    (1, -1, -0.001, -0.25, 2, 1, "ffffffffffffff15"),
]


@pytest.mark.parametrize("row", WHEEL_FEEDBACK_WIRE)
def test_wheel_feedback_multiplexed_keeps_the_wire_bytes(row: tuple) -> None:
    wheel, count, velocity, current, status, counter, wire = row
    side = ("Left", "Right")[wheel]
    values = {"Wheel": wheel, f"{side}Count": count, f"{side}Velocity": velocity,
              f"{side}Current": current, f"{side}DriverStatus": status, "Counter": counter}
    ref = DB.get_message_by_name("WheelFeedback")
    assert ref.is_multiplexed()
    assert CODEC.encode("WheelFeedback", values).hex() == wire
    assert ref.encode(values, strict=True).hex() == wire
    decoded = CODEC.message("WheelFeedback").decode(bytes.fromhex(wire))
    assert decoded == ref.decode(bytes.fromhex(wire), decode_choices=False)
    assert decoded == {**values, f"{side}Velocity": pytest.approx(velocity)}
    assert CODEC.decode(0x100, bytes.fromhex(wire), decode_choices=True)[1]["Wheel"] == side


def test_multiplexed_message_api_and_typed_errors() -> None:
    wf = CODEC.message("WheelFeedback")
    assert wf.is_multiplexed and wf.multiplexer is not None and wf.multiplexer.name == "Wheel"
    left, right = (wf.variants[k] for k in (0, 1))
    assert [s.name for s in left] == ["Wheel", "LeftCount", "LeftVelocity", "LeftCurrent",
                                      "LeftDriverStatus", "Counter"]
    assert wf.signal_sets == (left, right) and wf.signal("RightCount").multiplexer_ids == (1,)
    assert not CODEC.message("MotionState").is_multiplexed
    good = {"Wheel": 0, "LeftCount": 1, "LeftVelocity": 0.0, "LeftCurrent": 0.0,
            "LeftDriverStatus": 0, "Counter": 0}
    assert wf.encode(good) == wf.encode({"Wheel": "Left", "LeftCount": 1}, strict=False)
    with pytest.raises(EncodeError, match="missing the multiplexer signal 'Wheel'"):
        wf.encode({k: v for k, v in good.items() if k != "Wheel"})
    with pytest.raises(SignalRangeError, match="Wheel = 2"):
        wf.encode({**good, "Wheel": 2})
    with pytest.raises(SignalRangeError, match="Wheel = nan"):
        wf.encode({**good, "Wheel": math.nan})
    with pytest.raises(EncodeError, match=r"Wheel = 1 selects missing signals \['RightCount'"):
        wf.encode({**good, "Wheel": 1})
    with pytest.raises(EncodeError, match="unknown signals"):
        wf.encode({"Wheel": 1, "LeftCount": 1}, strict=False)
    with pytest.raises(EncodeError, match="choice"):
        wf.encode({**good, "Wheel": "Middle"})
    with pytest.raises(FrameLengthError):
        wf.decode(bytes(7))


SYNTHETIC = """VERSION ""
BS_:
BU_: A
BO_ 1 Mux2: 4 A
 SG_ Sel M : 0|2@1+ (1,0) [0|3] "" A
 SG_ Low m0 : 8|12@1+ (1,0) [0|4095] "" A
 SG_ High m1 : 8|12@1- (0.5,0) [-1024|1023.5] "V" A
 SG_ Tail : 20|12@1+ (1,0) [0|4095] "" A
"""


def test_multiplexer_with_undefined_values_and_shifted_signals(tmp_path: Path) -> None:
    path = tmp_path / "mux.dbc"
    path.write_text(SYNTHETIC)
    ours, ref = Codec(path).message("Mux2"), cantools.database.load_file(str(path))
    ref_msg = ref.get_message_by_name("Mux2")
    for values in ({"Sel": 0, "Low": 4095, "Tail": 7}, {"Sel": 1, "High": -3.5, "Tail": 4095}):
        data = ours.encode(values)
        assert data == ref_msg.encode(values, strict=True)
        assert ours.decode(data) == ref_msg.decode(data, decode_choices=False) == values
    with pytest.raises(ProtocolError, match="Sel = 2 selects no signals"):
        ours.decode(bytes([2, 0, 0, 0]))
    with pytest.raises(EncodeError, match="Sel = 3 selects no signals"):
        ours.encode({"Sel": 3, "Tail": 0})


def test_multiplexed_sets_with_different_layouts_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "mux.dbc"
    path.write_text(SYNTHETIC.replace("High m1 : 8|12@1-", "High m1 : 8|8@1-")
                    .replace("[-1024|1023.5]", "[-64|63.5]"))
    with pytest.raises(TypeError, match="share one byte layout"):
        Codec(path)


def test_multiplexer_that_selects_nothing_is_a_plain_signal(tmp_path: Path) -> None:
    path = tmp_path / "mux.dbc"
    path.write_text(SYNTHETIC.replace(" SG_ Low m0 : 8|12@1+ (1,0) [0|4095] \"\" A\n", "")
                    .replace(" SG_ High m1 : 8|12@1- (0.5,0) [-1024|1023.5] \"V\" A\n", ""))
    msg = Codec(path).message("Mux2")
    assert not msg.is_multiplexed and msg.signal_sets == (msg.signals,)
    data = msg.encode({"Sel": 3, "Tail": 9})
    ref = cantools.database.load_file(str(path)).get_message_by_name("Mux2")
    assert data == ref.encode({"Sel": 3, "Tail": 9}, strict=True)
    assert msg.decode(data) == ref.decode(data, decode_choices=False) == {"Sel": 3, "Tail": 9}
