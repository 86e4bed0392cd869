"""Serial framing: exact bytes, resynchronisation, error counting and fuzzing."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lowerbase.errors import FramingError
from lowerbase.protocol.framing import OVERHEAD, SOF, Deframer, Framer, crc16


def test_crc16_ccitt_false_check_value() -> None:
    assert crc16(b"123456789") == 0x29B1


def test_frame_bytes_match_the_documented_layout() -> None:
    frame = Framer().encode(0x020, bytes.fromhex("F40106FF3100"))
    assert frame.hex(" ").upper() == "AA 55 06 20 00 F4 01 06 FF 31 00 00 37 EA"
    assert len(frame) == 6 + OVERHEAD


def test_framer_rejects_what_cannot_be_framed() -> None:
    with pytest.raises(FramingError):
        Framer().encode(0x800, b"")
    with pytest.raises(FramingError):
        Framer().encode(0x10, bytes(9))


def _frames(n: int, seed: int = 1) -> list[tuple[int, bytes]]:
    rng = random.Random(seed)
    return [(rng.randrange(0x800), rng.randbytes(rng.randrange(9))) for _ in range(n)]


@settings(max_examples=50, deadline=None)
@given(chunks=st.lists(st.integers(1, 40), min_size=1, max_size=50))
def test_any_chunking_yields_the_same_frames(chunks: list[int]) -> None:
    framer = Framer()
    sent = _frames(30)
    stream = b"".join(framer.encode(i, d) for i, d in sent)
    deframer = Deframer()
    got = []
    pos = 0
    sizes = iter(chunks * 1000)
    while pos < len(stream):
        n = next(sizes)
        got += deframer.feed(stream[pos : pos + n])
        pos += n
    assert [(f.frame_id, f.data) for f in got] == sent
    assert deframer.stats.total_errors == 0 and deframer.stats.garbage_bytes == 0
    assert deframer.stats.seq_gaps == 0


def test_resynchronises_after_garbage_bad_crc_and_truncation() -> None:
    framer = Framer()
    a, b, c, d = (framer.encode(0x100 + i, bytes([i] * 8)) for i in range(4))
    corrupted = bytearray(b)
    corrupted[7] ^= 0x01  # payload bit flip -> CRC error
    stream = b"\x00\x13garbage" + a + bytes(corrupted) + c[:9] + d
    deframer = Deframer()
    got = deframer.feed(stream)
    assert [f.frame_id for f in got] == [0x100, 0x103]
    s = deframer.stats
    assert s.garbage_bytes == 9 + len(b) - 2  # leading junk + the rest of the bad frame
    assert s.bad_crc == 1
    assert s.truncated == 1
    assert s.seq_gaps == 2  # frames 1 and 2 never arrived whole


def test_bad_length_and_flush() -> None:
    deframer = Deframer()
    assert deframer.feed(SOF + b"\x09\x20\x00" + bytes(12)) == []
    assert deframer.stats.bad_length == 1
    deframer.feed(Framer().encode(0x10, b"\x01")[:-3])
    assert deframer.pending > 0
    deframer.flush()
    assert deframer.stats.truncated == 1 and deframer.pending == 0


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_fuzz_random_bytes_never_raise_and_stay_bounded(data: bytes) -> None:
    deframer = Deframer()
    for i in range(0, len(data), 7):
        deframer.feed(data[i : i + 7])
        assert deframer.pending < OVERHEAD + 8
    deframer.flush()


@settings(max_examples=100, deadline=None)
@given(noise=st.lists(st.tuples(st.integers(0, 400), st.binary(min_size=1, max_size=12)),
                      max_size=8))
def test_fuzz_valid_frames_survive_injected_noise(noise: list[tuple[int, bytes]]) -> None:
    framer = Framer()
    sent = _frames(40, seed=2)
    stream = bytearray(b"".join(framer.encode(i, d) for i, d in sent))
    for pos, junk in sorted(noise, reverse=True):
        stream[pos:pos] = junk
    got = Deframer().feed(bytes(stream))
    # every frame not hit by noise comes through intact, in order; nothing is invented
    assert [(f.frame_id, f.data) for f in got if (f.frame_id, f.data) in sent] == [
        x for x in sent if x in {(f.frame_id, f.data) for f in got}
    ]
    assert len(got) >= len(sent) - 2 * len(noise)
