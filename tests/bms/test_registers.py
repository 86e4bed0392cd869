"""The register table: encoding, threshold writes, and the generated documentation."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from lowerbase.bms.config import BatteryConfig
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.registers import (
    HOLDING_BASE,
    HOLDING_COUNT,
    HOLDING_REGISTERS,
    ILLEGAL_DATA_ADDRESS,
    ILLEGAL_DATA_VALUE,
    INPUT_COUNT,
    INPUT_REGISTERS,
    RegisterValueError,
    apply_holding_write,
    decode_protection,
    decode_snapshot,
    encode_protection,
    encode_snapshot,
    register,
    update_doc,
)
from lowerbase.bms.snapshot import SNAPSHOT_FIELDS

DOC = Path(__file__).resolve().parents[2] / "docs" / "bms-modbus.md"


def test_one_register_per_snapshot_field_contiguous() -> None:
    assert [r.name for r in INPUT_REGISTERS] == list(SNAPSHOT_FIELDS)
    for table in (INPUT_REGISTERS, HOLDING_REGISTERS):
        for a, b in itertools.pairwise(table):
            assert b.address == a.address + a.words


def test_snapshot_round_trip_at_register_resolution() -> None:
    pack = BatteryPack(soc=63.0)
    pack.step(5.0, 12.3)
    snap = pack.snapshot()
    words = encode_snapshot(snap)
    assert len(words) == INPUT_COUNT and all(0 <= w <= 0xFFFF for w in words)
    back = decode_snapshot(words)
    for reg in INPUT_REGISTERS:
        assert getattr(back, reg.name) == pytest.approx(getattr(snap, reg.name), abs=reg.scale / 2)
    assert decode_snapshot(encode_snapshot(back)) == back  # a fixed point


def test_word_layout() -> None:
    assert register("current").to_words(-1.0) == [0xFF9C]
    assert register("current").from_words([0xFF9C]) == -1.0
    assert register("bms_status").to_words(0x00030102) == [0x0003, 0x0102]
    assert register("voltage").to_words(1e9) == [0xFFFF]  # saturates


def test_protection_round_trip() -> None:
    protection = BatteryConfig().protection
    words = encode_protection(protection)
    assert len(words) == HOLDING_COUNT
    assert decode_protection(words) == protection
    assert words[0] == 3650 and words[1] == 3500  # cell OV trip/release in mV


def test_holding_write_validation() -> None:
    image = encode_protection(BatteryConfig().protection)
    _, cfg = apply_holding_write(image, HOLDING_BASE, [3700])
    assert cfg.cell_ov.trip == pytest.approx(3.7)
    with pytest.raises(RegisterValueError) as exc:
        apply_holding_write(image, HOLDING_BASE, [3400])  # trip below its release
    assert exc.value.exception_code == ILLEGAL_DATA_VALUE
    with pytest.raises(RegisterValueError) as exc:
        apply_holding_write(image, HOLDING_BASE, [9000])  # outside 2-5 V
    assert exc.value.exception_code == ILLEGAL_DATA_VALUE
    with pytest.raises(RegisterValueError) as exc:
        apply_holding_write(image, HOLDING_BASE + HOLDING_COUNT - 1, [1, 2])
    assert exc.value.exception_code == ILLEGAL_DATA_ADDRESS
    # a multi-register write that only makes sense as a whole is accepted
    _, cfg = apply_holding_write(image, HOLDING_BASE, [3400, 3300])
    assert (cfg.cell_ov.trip, cfg.cell_ov.release) == pytest.approx((3.4, 3.3))


def test_doc_is_up_to_date() -> None:
    text = DOC.read_text(encoding="utf-8")
    assert update_doc(text) == text, "run: python -m lowerbase.bms.registers docs/bms-modbus.md"
