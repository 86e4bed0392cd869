"""Bits on the wire of a classic CAN 2.0A data frame, with bit stuffing, and the bus's capacity.

A data frame with an 11-bit ID and n data bytes: SOF 1, ID 11, RTR 1, IDE 1, r0 1, DLC 4,
data 8n, CRC 15 (the stuffed region: 34 + 8n bits), then CRC delimiter 1, ACK slot and
delimiter 2, EOF 7, and 3 bits of interframe space: 47 + 8n bits unstuffed (44 of frame
overhead + 3 of interframe space). After five equal bits in the stuffed region the transmitter
inserts one of the opposite level, which counts toward the next run: at most
``floor((34 + 8n - 1) / 4)`` stuff bits (24 for n = 8). :func:`frame_bits` counts them for a
given frame exactly (CRC-15 included); :func:`mean_frame_bits` averages over uniformly random
IDs and data, seeded.
"""

from __future__ import annotations

import random

CRC15_POLY = 0x4599
INTERFRAME_SPACE = 3


def crc15(bits: list[int]) -> int:
    """CAN's CRC-15 (x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1) over a bit sequence."""
    crc = 0
    for bit in bits:
        top = ((crc >> 14) & 1) ^ bit
        crc = (crc << 1) & 0x7FFF
        if top:
            crc ^= CRC15_POLY
    return crc


def _bits(value: int, width: int) -> list[int]:
    return [(value >> (width - 1 - i)) & 1 for i in range(width)]


def stuff_bits(bits: list[int]) -> int:
    """How many stuff bits a transmitter inserts into ``bits`` (runs of five equal bits)."""
    count, run, last = 0, 0, -1
    for bit in bits:
        if bit == last:
            run += 1
        else:
            last, run = bit, 1
        if run == 5:
            count += 1
            last, run = 1 - bit, 1  # the stuff bit starts the next run
    return count


def frame_bits(frame_id: int, data: bytes) -> int:
    """Bits a classic data frame with an 11-bit ID occupies on the bus, stuffing and the
    3-bit interframe space included."""
    if not 0 <= frame_id <= 0x7FF or len(data) > 8:
        raise ValueError("a classic frame has an 11-bit ID and at most 8 data bytes")
    head = [0, *_bits(frame_id, 11), 0, 0, 0, *_bits(len(data), 4)]
    for byte in data:
        head += _bits(byte, 8)
    stuffed = head + _bits(crc15(head), 15)
    return len(stuffed) + stuff_bits(stuffed) + 1 + 2 + 7 + INTERFRAME_SPACE


def unstuffed_bits(n: int = 8) -> int:
    """47 + 8n: the frame without stuff bits, interframe space included."""
    return 44 + 8 * n + INTERFRAME_SPACE


def worst_case_bits(n: int = 8) -> int:
    """The longest a frame of n data bytes can be: every possible stuff bit inserted."""
    return unstuffed_bits(n) + (34 + 8 * n - 1) // 4


def mean_frame_bits(n: int = 8, samples: int = 20000, seed: int = 1) -> float:
    """Mean length over uniformly random 11-bit IDs and data bytes (seeded: reproducible)."""
    rng = random.Random(seed)
    total = 0
    for _ in range(samples):
        total += frame_bits(rng.randrange(0x800), bytes(rng.randrange(256) for _ in range(n)))
    return total / samples
