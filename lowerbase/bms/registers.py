"""The BMS Modbus register map: ONE table, with the codecs and the documentation built from it.

* Input registers (function code 04), from address 0: the measurements, one per
  :class:`~lowerbase.bms.snapshot.BmsSnapshot` field. Read-only by function code.
* Holding registers (function codes 03, 06, 16, 23), from address 0x0100: the protection
  thresholds, writable and kept in memory (lost on restart). A value outside a register's range,
  or a set of values that breaks a threshold rule (e.g. a release on the wrong side of its trip),
  is refused with ILLEGAL DATA VALUE (0x03) and nothing is written.

Addresses are the 0-based PDU addresses (``mbpoll`` needs ``-0`` or adds one). Multi-register
values are big-endian, high word first. Physical value = raw x scale.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal

from lowerbase.bms.config import PROTECTION_DIRECTIONS, ProtectionConfig, ProtectionLimit
from lowerbase.bms.snapshot import SNAPSHOT_FIELDS, BmsSnapshot
from lowerbase.bms.status import STATUS_DESCRIPTIONS
from lowerbase.errors import ConfigError, ModbusDeviceError

RegType = Literal["u16", "i16", "u32"]
Table = Literal["input", "holding"]

#: Modbus exception codes this device answers with
ILLEGAL_FUNCTION = 0x01
ILLEGAL_DATA_ADDRESS = 0x02
ILLEGAL_DATA_VALUE = 0x03
DEVICE_FAILURE = 0x04


class RegisterValueError(ModbusDeviceError):
    """A write the device refuses; ``exception_code`` is what goes on the wire."""

    def __init__(self, message: str, exception_code: int = ILLEGAL_DATA_VALUE) -> None:
        super().__init__(message)
        self.exception_code = exception_code


@dataclass(frozen=True)
class Register:
    """One value of the map."""

    #: snapshot field (input) or ``protection.limit`` path (holding)
    name: str
    table: Table
    address: int
    type: RegType
    #: physical value = raw x scale
    scale: float
    unit: str
    description: str
    #: writable range in physical units (holding registers)
    minimum: float | None = None
    maximum: float | None = None

    @property
    def words(self) -> int:
        return 2 if self.type == "u32" else 1

    @property
    def access(self) -> str:
        return "RW" if self.table == "holding" else "R"

    def to_raw(self, value: float) -> int:
        """Physical value -> raw integer (saturated to the type's range)."""
        raw = round(value / self.scale)
        lo, hi = {"u16": (0, 0xFFFF), "i16": (-0x8000, 0x7FFF), "u32": (0, 0xFFFFFFFF)}[self.type]
        return min(max(raw, lo), hi)

    def to_words(self, value: float) -> list[int]:
        raw = self.to_raw(value)
        if self.type == "u32":
            return [(raw >> 16) & 0xFFFF, raw & 0xFFFF]
        return [raw & 0xFFFF]

    def from_words(self, words: Sequence[int]) -> float:
        """Registers -> physical value (an int when the scale is 1)."""
        if self.type == "u32":
            raw = (words[0] << 16) | words[1]
        elif self.type == "i16":
            raw = words[0] - 0x10000 if words[0] & 0x8000 else words[0]
        else:
            raw = words[0]
        if self.scale == 1:
            return raw
        inverse = round(1 / self.scale)
        if abs(inverse * self.scale - 1) < 1e-12:
            return raw / inverse  # 3880 / 100 is 38.8 exactly; 3880 * 0.01 is not
        return raw * self.scale


INPUT_BASE = 0x0000
HOLDING_BASE = 0x0100


def _layout(table: Table, base: int, rows: Iterable[tuple]) -> tuple[Register, ...]:
    regs = []
    address = base
    for row in rows:
        reg = Register(row[0], table, address, *row[1:])
        regs.append(reg)
        address += reg.words
    return tuple(regs)


#: measurements, one per BmsSnapshot field, in snapshot order
INPUT_REGISTERS: tuple[Register, ...] = _layout("input", INPUT_BASE, [
    ("voltage", "u16", 0.01, "V", "Pack terminal voltage"),
    ("current", "i16", 0.01, "A", "Pack current, + charging, - discharging"),
    ("soc", "u16", 0.1, "%", "State of charge"),
    ("cell_voltage_max", "u16", 0.001, "V", "Highest cell voltage"),
    ("cell_voltage_min", "u16", 0.001, "V", "Lowest cell voltage"),
    ("temp_max", "i16", 0.1, "degC", "Hottest temperature sensor"),
    ("temp_min", "i16", 0.1, "degC", "Coldest temperature sensor"),
    ("capacity_remain", "u16", 0.01, "Ah", "Remaining capacity"),
    ("capacity_full", "u16", 0.01, "Ah", "Full-charge capacity (state of health)"),
    ("capacity_design", "u16", 0.01, "Ah", "Design capacity"),
    ("bms_status", "u32", 1, "", "Status word (bits below)"),
    ("charge_cycle", "u16", 1, "", "Completed charge cycles"),
    ("battery_cycle", "u16", 1, "", "Rated cycle life"),
    ("time_remain", "u16", 1, "min", "Time to empty at the recent average current; "
                                      "65535 = not discharging"),
    ("switch_status", "u16", 1, "", "Bit 0 discharge switch closed, bit 1 charge switch closed"),
    ("charge_status", "u16", 1, "", "0 = discharge, 1 = charging"),
    ("charge_mode", "u16", 1, "", "0 = manual (plugged), 1 = automatic (docking station)"),
    ("submodule", "u16", 1, "", "Battery submodule number"),
])

_LIMIT_TEXT = {
    "cell_ov": ("cell over-voltage", "V", 0.001, "u16", 2.0, 5.0),
    "cell_uv": ("cell under-voltage", "V", 0.001, "u16", 1.5, 4.5),
    "charge_oc": ("charge over-current", "A", 0.1, "u16", 0.1, 3000.0),
    "discharge_oc": ("discharge over-current", "A", 0.1, "u16", 0.1, 3000.0),
    "charge_ot": ("charge over-temperature", "degC", 0.1, "i16", -40.0, 120.0),
    "charge_ut": ("charge under-temperature", "degC", 0.1, "i16", -40.0, 120.0),
    "discharge_ot": ("discharge over-temperature", "degC", 0.1, "i16", -40.0, 120.0),
    "discharge_ut": ("discharge under-temperature", "degC", 0.1, "i16", -40.0, 120.0),
}


def _holding_rows() -> list[tuple]:
    rows: list[tuple] = []
    for name in PROTECTION_DIRECTIONS:
        text, unit, scale, typ, lo, hi = _LIMIT_TEXT[name]
        rows += [
            (f"{name}.trip", typ, scale, unit, f"{text.capitalize()} trip", lo, hi),
            (f"{name}.release", typ, scale, unit, f"{text.capitalize()} release", lo, hi),
            (f"{name}.trip_delay_s", "u16", 0.001, "s", f"{text.capitalize()} trip delay",
             0.0, 60.0),
            (f"{name}.release_delay_s", "u16", 0.001, "s", f"{text.capitalize()} release delay",
             0.0, 60.0),
        ]
    rows.append(("soc_low_percent", "u16", 0.1, "%", "Low-SOC warning level", 0.0, 100.0))
    return rows


#: protection thresholds (writable)
HOLDING_REGISTERS: tuple[Register, ...] = _layout("holding", HOLDING_BASE, _holding_rows())

INPUT_COUNT = sum(r.words for r in INPUT_REGISTERS)
HOLDING_COUNT = sum(r.words for r in HOLDING_REGISTERS)

assert tuple(r.name for r in INPUT_REGISTERS) == SNAPSHOT_FIELDS, "one register per field"


# -- measurements ---------------------------------------------------------------------------


def _input_codec() -> tuple[tuple[str, float, int, int, bool, int, int, float | None], ...]:
    """Per input register, what :meth:`Register.to_words` / :meth:`Register.from_words` look
    up on every call: (name, scale, lo, hi, two words, offset, kind 0 u16 / 1 i16 / 2 u32,
    the exact inverse of the scale or None)."""
    rows = []
    for reg in INPUT_REGISTERS:
        lo, hi = {"u16": (0, 0xFFFF), "i16": (-0x8000, 0x7FFF), "u32": (0, 0xFFFFFFFF)}[reg.type]
        inverse: float | None = None
        if reg.scale != 1:
            inv = round(1 / reg.scale)
            if abs(inv * reg.scale - 1) < 1e-12:
                inverse = inv
        rows.append((reg.name, reg.scale, lo, hi, reg.words == 2, reg.address - INPUT_BASE,
                     ("u16", "i16", "u32").index(reg.type), inverse))
    return tuple(rows)


_INPUT_CODEC = _input_codec()


def encode_snapshot(snapshot: BmsSnapshot) -> list[int]:
    """The input-register image (``INPUT_COUNT`` words from address 0) of ``snapshot``:
    each register's :meth:`Register.to_words`, written out."""
    words: list[int] = []
    append = words.append
    for name, scale, lo, hi, wide, _, _, _ in _INPUT_CODEC:
        raw = min(max(round(getattr(snapshot, name) / scale), lo), hi)
        if wide:
            append((raw >> 16) & 0xFFFF)
        append(raw & 0xFFFF)
    return words


def decode_snapshot(words: Sequence[int]) -> BmsSnapshot:
    """Inverse of :func:`encode_snapshot` (at the registers' resolution): each register's
    :meth:`Register.from_words`, written out."""
    if len(words) != INPUT_COUNT:
        raise ModbusDeviceError(f"expected {INPUT_COUNT} input registers, got {len(words)}")
    values: list[float] = []
    append = values.append
    for _, scale, _, _, _, i, kind, inverse in _INPUT_CODEC:
        if kind == 2:
            raw = (words[i] << 16) | words[i + 1]
        elif kind == 1:
            raw = words[i] - 0x10000 if words[i] & 0x8000 else words[i]
        else:
            raw = words[i]
        if scale == 1:
            append(raw)
        elif inverse is not None:
            append(raw / inverse)  # 3880 / 100 is 38.8 exactly; 3880 * 0.01 is not
        else:
            append(raw * scale)
    return BmsSnapshot(*values)  # type: ignore[arg-type]


# -- thresholds -----------------------------------------------------------------------------


def _protection_value(config: ProtectionConfig, name: str) -> float:
    if "." in name:
        limit, attr = name.split(".")
        return float(getattr(getattr(config, limit), attr))
    return float(getattr(config, name))


def encode_protection(config: ProtectionConfig) -> list[int]:
    """The holding-register image (``HOLDING_COUNT`` words from ``HOLDING_BASE``)."""
    words: list[int] = []
    for reg in HOLDING_REGISTERS:
        words += reg.to_words(_protection_value(config, reg.name))
    return words


def decode_protection(words: Sequence[int]) -> ProtectionConfig:
    """Holding-register image -> thresholds; :class:`RegisterValueError` (ILLEGAL DATA VALUE)
    for a value out of its register's range or thresholds that break a rule."""
    if len(words) != HOLDING_COUNT:
        raise ModbusDeviceError(f"expected {HOLDING_COUNT} holding registers, got {len(words)}")
    limits: dict[str, dict[str, float]] = {name: {} for name in PROTECTION_DIRECTIONS}
    extra: dict[str, float] = {}
    for reg in HOLDING_REGISTERS:
        i = reg.address - HOLDING_BASE
        value = float(reg.from_words(words[i : i + reg.words]))
        assert reg.minimum is not None and reg.maximum is not None
        if not reg.minimum - 1e-9 <= value <= reg.maximum + 1e-9:
            raise RegisterValueError(
                f"register {reg.address:#06x} ({reg.name}) = {value:g} {reg.unit} is outside "
                f"[{reg.minimum:g}, {reg.maximum:g}]"
            )
        if "." in reg.name:
            limit, attr = reg.name.split(".")
            limits[limit][attr] = value
        else:
            extra[reg.name] = value
    try:
        return ProtectionConfig(
            **{name: ProtectionLimit(**v) for name, v in limits.items()},
            soc_low_percent=extra["soc_low_percent"],
        )
    except ConfigError as exc:
        raise RegisterValueError(str(exc)) from None


def apply_holding_write(
    current: Sequence[int], address: int, values: Sequence[int]
) -> tuple[list[int], ProtectionConfig]:
    """The holding image and thresholds after writing ``values`` at ``address``.

    Raises :class:`RegisterValueError` with ILLEGAL DATA ADDRESS for addresses outside the
    holding table and ILLEGAL DATA VALUE for values the thresholds cannot take.
    """
    offset = address - HOLDING_BASE
    if offset < 0 or offset + len(values) > HOLDING_COUNT or not values:
        raise RegisterValueError(
            f"holding registers {address:#06x}+{len(values)} do not exist", ILLEGAL_DATA_ADDRESS
        )
    image = list(current)
    image[offset : offset + len(values)] = [int(v) & 0xFFFF for v in values]
    return image, decode_protection(image)


def register(name: str) -> Register:
    """The register called ``name`` (either table)."""
    for reg in INPUT_REGISTERS + HOLDING_REGISTERS:
        if reg.name == name:
            return reg
    raise KeyError(name)


# -- documentation --------------------------------------------------------------------------


def _fmt_scale(scale: float) -> str:
    return f"{scale:g}"


def markdown_tables() -> str:
    """The register and status-bit tables of ``docs/bms-modbus.md``."""
    lines = [
        "### Input registers (function code 04, read-only)",
        "",
        "| Address | Name | Type | Scale | Unit | Access | Description |",
        "|---|---|---|---|---|---|---|",
    ]
    for reg in INPUT_REGISTERS:
        addr = f"{reg.address} ({reg.address:#06x})"
        if reg.words == 2:
            addr = f"{reg.address}-{reg.address + 1} ({reg.address:#06x})"
        lines.append(
            f"| {addr} | `{reg.name}` | {reg.type} | {_fmt_scale(reg.scale)} | {reg.unit} "
            f"| {reg.access} | {reg.description} |"
        )
    lines += [
        "",
        "### Holding registers (function codes 03, 06, 16, 23, read-write)",
        "",
        "| Address | Name | Type | Scale | Unit | Access | Range | Description |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for reg in HOLDING_REGISTERS:
        lines.append(
            f"| {reg.address} ({reg.address:#06x}) | `{reg.name}` | {reg.type} "
            f"| {_fmt_scale(reg.scale)} | {reg.unit} | {reg.access} "
            f"| {reg.minimum:g} … {reg.maximum:g} | {reg.description} |"
        )
    lines += [
        "",
        "### Status word bits (`bms_status`, CAN `BmsStatus.Status`)",
        "",
        "| Bit | Mask | Name | Meaning |",
        "|---|---|---|---|",
    ]
    for flag, text in STATUS_DESCRIPTIONS.items():
        bit = int(flag).bit_length() - 1
        lines.append(f"| {bit} | 0x{int(flag):08X} | `{flag.name}` | {text} |")
    return "\n".join(lines) + "\n"


def defaults_table(config: ProtectionConfig) -> dict[str, float]:
    """Threshold values by register name (for printing and tests)."""
    return {reg.name: _protection_value(config, reg.name) for reg in HOLDING_REGISTERS}



DOC_BEGIN = "<!-- BEGIN GENERATED by `python -m lowerbase.bms.registers`; do not edit -->"
DOC_END = "<!-- END GENERATED -->"


def update_doc(text: str) -> str:
    """``text`` with the part between :data:`DOC_BEGIN` and :data:`DOC_END` regenerated."""
    head, sep, rest = text.partition(DOC_BEGIN)
    _, sep2, tail = rest.partition(DOC_END)
    if not sep or not sep2:
        raise ValueError("the document has no generated-section markers")
    return f"{head}{DOC_BEGIN}\n{markdown_tables()}{DOC_END}{tail}"


if __name__ == "__main__":  # pragma: no cover - regenerates docs/bms-modbus.md
    import sys
    from pathlib import Path

    doc = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/bms-modbus.md")
    doc.write_text(update_doc(doc.read_text(encoding="utf-8")), encoding="utf-8")
    print(f"updated {doc}")
