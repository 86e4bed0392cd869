"""Every decode entry point of the compiled codec against cantools, on random payloads.

The codec compiles several decoders per message (checked by a ``strict`` argument, with the
range checks built in, returning the values or (name, values)); ``MessageCodec.decode``,
``Codec.decode`` and ``Codec.decoders()`` pick among them. Whichever is picked, the result
(or the typed error) must be the one cantools' values imply.
"""

from __future__ import annotations

from typing import Any

import cantools
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lowerbase.errors import ProtocolError, SignalRangeError
from lowerbase.protocol.codec import DBC_PATH, Codec, MessageCodec

LEGGED_DBC = DBC_PATH.with_name("legged.dbc")

#: small spanning fields: signed and unsigned, full and restricted ranges, scaled, offset,
#: Intel and Motorola; a byte of small fields with an unused value
SYNTHETIC = """VERSION ""
BS_:
BU_: A
BO_ 1 Narrow: 8 A
 SG_ Small : 0|3@1+ (1,0) [1|6] "" A
 SG_ Flag : 3|1@1+ (1,0) [0|1] "" A
 SG_ TempA : 4|12@1- (0.1,0) [-204.8|204.7] "C" A
 SG_ TempB : 16|12@1- (0.1,-5) [-50|50] "C" A
 SG_ Gain : 28|10@1+ (0.25,1) [1|200] "" A
 SG_ Tail : 38|26@1+ (1,0) [0|67108863] "" A
BO_ 2 NarrowBig: 6 A
 SG_ Pos : 7|16@0+ (0.01,-327.68) [-327.68|327.67] "rad" A
 SG_ Vel : 23|12@0+ (0.02,-40.96) [-40|40] "rad/s" A
 SG_ Cur : 27|12@0+ (0.01,-20.48) [-20.48|20.47] "A" A
"""


def _entry_points(codec: Codec, msg: MessageCodec, payload: bytes) -> dict[str, Any]:
    """What each way of decoding gives: the values, or the type of the error raised."""
    def run(fn: Any) -> Any:
        try:
            return fn()
        except ProtocolError as exc:  # the message must not chain the internal TypeError
            assert exc.__cause__ is None
            assert exc.__suppress_context__ or exc.__context__ is None
            return type(exc)
    fid = msg.frame_id
    return {
        "msg strict": run(lambda: msg.decode(payload)),
        "msg loose": run(lambda: msg.decode(payload, strict=False)),
        "msg choices": run(lambda: msg.decode(payload, decode_choices=True)),
        "codec strict": run(lambda: codec.decode(fid, payload)[1]),
        "codec positional": run(lambda: codec.decode(fid, payload, False, True)[1]),
        "codec loose": run(lambda: codec.decode(fid, payload, strict=False)[1]),
        "codec choices": run(lambda: codec.decode(fid, payload, decode_choices=True)[1]),
        "table strict": run(lambda: codec.decoders()[fid](payload, True)[1]),
        "table loose": run(lambda: codec.decoders()[fid](payload, False)[1]),
    }


def _check(codec: Codec, db: Any, msg: MessageCodec, payload: bytes) -> None:
    ref = db.get_message_by_name(msg.name)
    got = _entry_points(codec, msg, payload)
    try:
        expected = ref.decode(payload, decode_choices=False)
    except cantools.database.DecodeError:  # a multiplexer value without signals
        assert set(got.values()) == {ProtocolError}, msg.name
        return
    named = {k: v if isinstance(v, (int, float)) else str(v)
             for k, v in ref.decode(payload, decode_choices=True).items()}
    in_range = all(s.minimum <= expected[s.name] <= s.maximum
                   for s in msg.signals if s.name in expected)
    want = {key: (named if "choices" in key else expected) if in_range or "loose" in key
            else SignalRangeError for key in got}
    # repr of the sorted items: NaN float signals compare unequal to themselves
    assert _norm(got) == _norm(want), msg.name


def _norm(results: dict[str, Any]) -> dict[str, str]:
    return {key: repr(sorted(v.items()) if isinstance(v, dict) else v)
            for key, v in results.items()}


CHASSIS = Codec(DBC_PATH)
CHASSIS_DB = cantools.database.load_file(str(DBC_PATH))


@pytest.mark.parametrize("name", [m.name for m in CHASSIS])
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_every_decode_path_of_the_chassis_catalog_agrees_with_cantools(
    name: str, data: st.DataObject
) -> None:
    msg = CHASSIS.message(name)
    _check(CHASSIS, CHASSIS_DB, msg, data.draw(st.binary(min_size=msg.length,
                                                         max_size=msg.length)))


LEGGED = Codec(LEGGED_DBC)
LEGGED_DB = cantools.database.load_file(str(LEGGED_DBC))


@pytest.mark.parametrize("name", [m.name for m in LEGGED])
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_every_decode_path_of_the_legged_catalog_agrees_with_cantools(
    name: str, data: st.DataObject
) -> None:
    msg = LEGGED.message(name)
    _check(LEGGED, LEGGED_DB, msg, data.draw(st.binary(min_size=msg.length,
                                                       max_size=msg.length)))


@pytest.fixture(scope="module")
def narrow(tmp_path_factory: pytest.TempPathFactory) -> tuple[Codec, Any]:
    path = tmp_path_factory.mktemp("narrow") / "narrow.dbc"
    path.write_text(SYNTHETIC)
    return Codec(path), cantools.database.load_file(str(path))


@settings(max_examples=400, deadline=None)
@given(payload=st.binary(min_size=8, max_size=8), big=st.binary(min_size=6, max_size=6))
def test_small_spanning_fields_agree_with_cantools(narrow: tuple[Codec, Any], payload: bytes,
                                                    big: bytes) -> None:
    codec, db = narrow
    _check(codec, db, codec.message("Narrow"), payload)
    _check(codec, db, codec.message("NarrowBig"), big)


def test_small_spanning_fields_edges(narrow: tuple[Codec, Any]) -> None:
    """The raw extremes of every small field, in and out of range, through every path."""
    codec, db = narrow
    for name in ("Narrow", "NarrowBig"):
        msg = codec.message(name)
        for raw in (0, 1, 0x7FF, 0x800, 0xFFF, 0x555, 0xAAA, 0x3FFFFFF):
            word = sum((raw & ((1 << s.length) - 1)) << s.start for s in msg.signals)
            payload = word.to_bytes(msg.length, "little")
            _check(codec, db, msg, payload[::-1] if msg.big_endian else payload)
