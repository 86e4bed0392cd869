"""Bits of a classic CAN frame on the wire, checked against independent implementations."""

from __future__ import annotations

import random
import re

from lowerbase.protocol import busload


def _crc15_by_division(bits: list[int]) -> int:
    """The CRC as the remainder of (message * x^15) / generator, by long division."""
    generator = (1 << 15) | busload.CRC15_POLY
    value = int("".join(map(str, bits)) or "0", 2) << 15
    for shift in range(value.bit_length() - 16, -1, -1):
        if value >> (shift + 15) & 1:
            value ^= generator << shift
    return value


def _stuff(bits: str) -> str:
    """The transmitted stream: a stuff bit of the other level after every five equal bits."""
    out, run, last = [], 0, ""
    for bit in bits:
        out.append(bit)
        run = run + 1 if bit == last else 1
        last = bit
        if run == 5:
            last = "1" if bit == "0" else "0"
            out.append(last)
            run = 1
    return "".join(out)


def _frame_stream(frame_id: int, data: bytes) -> str:
    head = "0" + f"{frame_id:011b}" + "000" + f"{len(data):04b}" + "".join(f"{b:08b}" for b in data)
    return head + f"{_crc15_by_division([int(c) for c in head]):015b}"


def test_crc15_matches_long_division() -> None:
    rng = random.Random(5)
    for _ in range(300):
        bits = [rng.randrange(2) for _ in range(rng.randrange(1, 100))]
        assert busload.crc15(bits) == _crc15_by_division(bits)


def test_frame_bits_against_the_stuffed_stream() -> None:
    rng = random.Random(6)
    cases = [(0, bytes(8)), (0x7FF, b"\xff" * 8), (0x555, b"\x55" * 8), (0x10, b"")]
    cases += [(rng.randrange(0x800), bytes(rng.randrange(256) for _ in range(rng.randrange(9))))
              for _ in range(500)]
    for frame_id, data in cases:
        stream = _stuff(_frame_stream(frame_id, data))
        assert not re.search("000000|111111", stream)  # what a receiver checks
        assert busload.frame_bits(frame_id, data) == len(stream) + 1 + 2 + 7 + 3
        assert busload.frame_bits(frame_id, data) <= busload.worst_case_bits(len(data))


def test_capacity_figures() -> None:
    assert busload.unstuffed_bits(8) == 44 + 64 + 3 == 111
    assert busload.worst_case_bits(8) == 111 + 24
    assert 500_000 / busload.unstuffed_bits(8) == 4504.504504504504
    mean = busload.mean_frame_bits(8, samples=4000, seed=2)
    assert 112.5 < mean < 116.0  # about one stuff bit per 30 random bits over 98 stuffed bits
    # all-zero data and ID 0: the stuffed region is nearly one long run, close to the worst case
    assert busload.frame_bits(0, bytes(8)) >= busload.worst_case_bits(8) - 8
