"""A fast, strict codec compiled from the DBC catalog.

cantools parses ``chassis.dbc`` once; for every message this module then generates a pair of
plain Python functions (``encode``/``decode``) with the bit positions, masks, scales, offsets
and raw range limits inlined as constants, the way ``collections.namedtuple`` builds its class.
The arithmetic is cantools' own (``raw * scale + offset`` to decode, ``round((v - offset) / scale)``
to encode, exact integer division where scale and offset are integers), so results agree with
``cantools`` bit for bit; a property test holds them to it.

A multiplexed message (one multiplexer signal, as WheelFeedback's ``Wheel``) compiles into one
function per direction that branches on the multiplexer value: decode returns the multiplexer,
the signals present in every frame and only the selected value's signals, as cantools does;
encode takes the multiplexer value and exactly those signals.

Strict by design: a wrong payload length, an unknown frame ID or name, a missing or unknown
signal, a non-finite value or a value outside the catalog's range raises a typed
:class:`~lowerbase.errors.ProtocolError`; nothing is clipped or guessed silently.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, NoReturn, Protocol

import cantools
from cantools.database.conversion import (
    IdentityConversion,
    LinearConversion,
    LinearIntegerConversion,
    NamedSignalConversion,
)

from lowerbase.errors import (
    EncodeError,
    FrameLengthError,
    ProtocolError,
    SignalRangeError,
    UnknownMessageError,
)

DBC_PATH = Path(__file__).with_name("chassis.dbc")

SignalValue = int | float | str
Signals = dict[str, SignalValue]
Payload = bytes | bytearray | memoryview


class DecodeFunction(Protocol):
    def __call__(
        self, frame_id: int, data: bytes | bytearray | memoryview, *,
        decode_choices: bool = False, strict: bool = True,
    ) -> tuple[str, Signals]: ...

_F32 = struct.Struct("<f")
_F64 = struct.Struct("<d")


@dataclass(frozen=True)
class SignalSpec:
    """One signal as the catalog defines it (Intel byte order, start bit = LSB)."""

    name: str
    start: int
    length: int
    is_signed: bool
    is_float: bool
    scale: float
    offset: float
    minimum: float | None
    maximum: float | None
    unit: str
    comment: str
    choices: Mapping[int, str]
    #: raw (integer) limits implied by minimum/maximum and the bit width
    raw_min: int
    raw_max: int
    #: how cantools converts: "identity", "int" (integer scale/offset) or "linear"
    kind: str
    #: the message's multiplexer signal (selects which other signals a frame carries)
    is_multiplexer: bool = False
    #: multiplexer values whose frames carry this signal; empty = every frame
    multiplexer_ids: tuple[int, ...] = ()
    #: "little_endian" (Intel), or "big_endian" (Motorola): ``start`` is then the LSB of the
    #: signal in the byte-reversed payload, ``dbc_start`` the DBC's own (MSB) start bit
    byte_order: str = "little_endian"
    dbc_start: int = -1

    @property
    def mask(self) -> int:
        return (1 << self.length) - 1


def _raw_limits(sig: Any, kind: str) -> tuple[int, int]:
    if sig.is_signed:
        lo, hi = -(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1
    else:
        lo, hi = 0, (1 << sig.length) - 1
    if sig.conversion.is_float:
        return lo, hi
    scale = sig.scale
    offset = sig.offset
    if sig.minimum is not None:
        lo = max(lo, math.ceil((sig.minimum - offset) / scale - 1e-9))
    if sig.maximum is not None:
        hi = min(hi, math.floor((sig.maximum - offset) / scale + 1e-9))
    return lo, hi


def _conversion_kind(conv: Any) -> str:
    if isinstance(conv, NamedSignalConversion):
        conv = conv._conversion
    if isinstance(conv, IdentityConversion):
        return "identity"
    if isinstance(conv, LinearIntegerConversion):
        return "int"
    if isinstance(conv, LinearConversion):
        return "linear"
    raise TypeError(f"unsupported cantools conversion {conv!r}")


def _tree_order(tree: list[Any]) -> list[str]:
    """Signal names in cantools' signal-tree order: a multiplexer, then its values' signals."""
    names: list[str] = []
    for node in tree:
        if isinstance(node, str):
            names.append(node)
            continue
        for mux, by_value in node.items():
            names.append(mux)
            for sub in by_value.values():
                names += [n for n in _tree_order(sub) if n not in names]
    return names


def _direct_var(s: SignalSpec) -> str | None:
    """The struct field of a signal that fills whole, aligned bytes of size 1, 2, 4 or 8."""
    return f"d{s.start // 8}" if s.start % 8 == 0 and s.length in (8, 16, 32, 64) else None


class MessageCodec:
    """Encoder and decoder of one catalog message."""

    def __init__(self, msg: Any) -> None:
        if msg.is_container:
            raise TypeError(f"{msg.name}: container messages are not supported")
        self.name: str = msg.name
        self.frame_id: int = msg.frame_id
        self.is_extended_id: bool = msg.is_extended_frame
        self.length: int = msg.length
        #: cycle time [s], or None for event messages
        self.cycle_time: float | None = msg.cycle_time / 1000.0 if msg.cycle_time else None
        self.senders: tuple[str, ...] = tuple(msg.senders)
        self.comment: str = msg.comment or ""
        specs = []
        by_name = {sig.name: sig for sig in msg.signals}
        orders = {sig.byte_order for sig in msg.signals}
        if len(orders) > 1:
            raise TypeError(f"{msg.name}: mixed byte orders in one message are not supported")
        #: a big-endian (Motorola) message is compiled as the little-endian message of its
        #: byte-reversed payload: in ``int.from_bytes(data, "big")`` every Motorola signal is
        #: one contiguous bit field, which is the little-endian reading of ``data[::-1]``
        self.big_endian: bool = orders == {"big_endian"}
        for sig in (by_name[n] for n in _tree_order(msg.signal_tree)):
            start = sig.start
            if self.big_endian:  # the MSB's position in the reversed payload, minus the width
                start = (msg.length - 1 - sig.start // 8) * 8 + sig.start % 8 - sig.length + 1
            kind = _conversion_kind(sig.conversion)
            lo, hi = _raw_limits(sig, kind)
            specs.append(
                SignalSpec(
                    name=sig.name,
                    start=start,
                    length=sig.length,
                    is_signed=sig.is_signed,
                    is_float=sig.conversion.is_float,
                    scale=sig.scale,
                    offset=sig.offset,
                    minimum=sig.minimum,
                    maximum=sig.maximum,
                    unit=sig.unit or "",
                    comment=sig.comment or "",
                    choices={int(k): str(v) for k, v in (sig.choices or {}).items()},
                    raw_min=lo,
                    raw_max=hi,
                    kind=kind,
                    is_multiplexer=bool(sig.is_multiplexer),
                    multiplexer_ids=tuple(sig.multiplexer_ids or ()),
                    byte_order=sig.byte_order,
                    dbc_start=sig.start,
                )
            )
        self.signals: tuple[SignalSpec, ...] = tuple(specs)
        muxes = [s for s in specs if s.is_multiplexer]
        if len(muxes) > 1 or any(s.multiplexer_ids for s in muxes):
            raise TypeError(f"{msg.name}: one multiplexer per message is supported, no nesting")
        #: multiplexer value -> the signals a frame with that value carries ({} if plain)
        self.variants: dict[int, tuple[SignalSpec, ...]] = {
            k: tuple(s for s in specs if not s.multiplexer_ids or k in s.multiplexer_ids)
            for k in sorted({k for s in specs for k in s.multiplexer_ids})
        }
        #: the multiplexer signal, or None for a plain message (also one whose multiplexer
        #: selects nothing: every frame then carries every signal)
        self.multiplexer: SignalSpec | None = muxes[0] if muxes and self.variants else None
        if self.multiplexer and (self.multiplexer.kind != "identity"
                                 or self.multiplexer.is_signed):
            raise TypeError(f"{msg.name}: the multiplexer must be an unsigned integer signal")
        self.signal_names: frozenset[str] = frozenset(s.name for s in specs)
        self._by_name = {s.name: s for s in specs}
        self._choice_numbers = {
            s.name: {v: k for k, v in s.choices.items()} for s in specs if s.choices
        }
        self._decode = self._compile_decode()
        self._encode = self._compile_encode()

    # -- public API ---------------------------------------------------------------------------

    @property
    def is_periodic(self) -> bool:
        return self.cycle_time is not None

    @property
    def is_multiplexed(self) -> bool:
        return self.multiplexer is not None

    @property
    def signal_sets(self) -> tuple[tuple[SignalSpec, ...], ...]:
        """The signal sets a frame can carry: one per multiplexer value, or all signals."""
        return tuple(self.variants.values()) or (self.signals,)

    def signals_of(self, values: Mapping[str, Any]) -> tuple[SignalSpec, ...]:
        """The signals of the frame these (decoded or to be encoded) values select."""
        if self.multiplexer is None:
            return self.signals
        mux = _to_number(self, self.multiplexer.name, values.get(self.multiplexer.name, 0))
        found = self.variants.get(int(mux)) if math.isfinite(mux) and mux == int(mux) else None
        if found is None:
            _mux_error(self, mux)
        return found

    @property
    def has_counter(self) -> bool:
        return "Counter" in self.signal_names

    def signal(self, name: str) -> SignalSpec:
        try:
            return self._by_name[name]
        except KeyError:
            raise EncodeError(f"{self.name} has no signal {name!r}") from None

    def decode(
        self, data: bytes | bytearray | memoryview, decode_choices: bool = False,
        strict: bool = True,
    ) -> Signals:
        """Decode a payload into physical values.

        ``strict`` (default) raises :class:`SignalRangeError` for a value outside the
        catalog range; ``decode_choices`` replaces values that have a name by the name.
        """
        # no keyword-only parameters: CPython (3.11+) specializes only calls of functions
        # without them; the functions are read into locals (``self._f(...)`` is a method
        # lookup, which CPython does not specialize for an instance's attribute)
        if strict and not decode_choices:
            fast = self._decode_strict
            return fast(data)
        loose = self._decode
        values: Signals = loose(data, strict)  # type: ignore[arg-type]  # any buffer
        if decode_choices:
            for name, table in ((s.name, s.choices) for s in self.signals if s.choices):
                raw = values.get(name)
                if isinstance(raw, int) and raw in table:
                    values[name] = table[raw]
        return values

    def encode(self, values: Mapping[str, Any], *, strict: bool = True) -> bytes:
        """Encode physical values (numbers, or choice names) into a payload.

        With ``strict`` every signal must be given and no unknown one; without it, missing
        signals encode as 0 where 0 is in range. A multiplexed message takes the multiplexer
        value and exactly the signals it selects (non-strict: a missing multiplexer is 0).
        """
        if not strict:
            signals = self.signals_of(values)
            unknown = sorted(set(values) - {s.name for s in signals})
            if unknown:
                raise EncodeError(f"{self.name}: unknown signals {unknown}")
            values = {**{s.name: 0 for s in signals}, **values}
        return self._encode(values)

    def choice_number(self, signal: str, name: str) -> int:
        try:
            return self._choice_numbers[signal][name]
        except KeyError:
            raise EncodeError(f"{self.name}.{signal}: no choice named {name!r}") from None

    # -- code generation ----------------------------------------------------------------------

    def _layout(self, signals: tuple[SignalSpec, ...]) -> tuple[str, list[tuple[str, int, int]]]:
        """Split the payload into struct fields.

        A signal that fills whole, aligned bytes of size 1, 2, 4 or 8 is one struct field of its
        own (``d<byte>``); the other bytes form maximal runs of unsigned fields (``p<byte>``) from
        which the remaining signals are shifted and masked. Returns the struct format and, per
        field, its variable name, first bit and width.
        """
        direct: dict[int, SignalSpec] = {}
        for s in signals:
            if _direct_var(s):
                direct[s.start // 8] = s
        covered = {b for i, s in direct.items() for b in range(i, i + s.length // 8)}
        fmt = "<"
        fields: list[tuple[str, int, int]] = []
        byte = 0
        while byte < self.length:
            if byte in direct:
                s = direct[byte]
                n = s.length // 8
                if s.is_float:
                    fmt += "f" if n == 4 else "d"
                else:
                    code = {1: "b", 2: "h", 4: "i", 8: "q"}[n]
                    fmt += code if s.is_signed else code.upper()
                fields.append((f"d{byte}", byte * 8, s.length))
                byte += n
                continue
            if byte in covered:  # pragma: no cover - overlapping signals are rejected by cantools
                raise TypeError(f"{self.name}: overlapping signals at byte {byte}")
            run = byte
            while run < self.length and run not in direct:
                run += 1
            # one run of unsigned pieces (8, 4, 2 or 1 bytes), joined back into one integer
            pos = byte
            pieces = []
            while pos < run:
                n = next(k for k in (8, 4, 2, 1) if pos + k <= run)
                fmt += {1: "B", 2: "H", 4: "I", 8: "Q"}[n]
                pieces.append((f"p{pos}", pos * 8, n * 8))
                pos += n
            fields.extend(pieces)
            byte = run
        return fmt, fields

    def _piece_expr(self, s: SignalSpec, pieces: list[tuple[str, int, int]]) -> str:
        """Expression extracting signal ``s`` (unsigned raw bits) from the run pieces."""
        parts = [(n, first, w) for n, first, w in pieces
                 if first < s.start + s.length and first + w > s.start]
        base = parts[0][1]
        joined = " | ".join(n if first == base else f"({n} << {first - base})"
                            for n, first, _ in parts)
        expr = f"({joined})" if len(parts) > 1 else joined
        shift = s.start - base
        if shift:
            expr = f"({expr} >> {shift})"
        width = sum(w for _, _, w in parts)
        if shift + s.length < width:  # bits above the signal
            expr = f"{expr} & {s.mask:#x}"
        return expr

    def _raw_expr(self, s: SignalSpec, fields: list[tuple[str, int, int]]) -> str:
        """Expression of the unsigned raw bits of ``s`` from the decode fields (the
        multiplexer, read before the branch on its value)."""
        names = {f[0] for f in fields}
        if _direct_var(s) in names:
            return str(_direct_var(s))
        byte = s.start // 8
        if f"t{byte}" in names and (s.start + s.length - 1) // 8 == byte:
            shift = s.start - 8 * byte
            return f"(t{byte} >> {shift}) & {s.mask:#x}" if shift else f"t{byte} & {s.mask:#x}"
        return self._piece_expr(s, [f for f in fields if f[0].startswith("p")])

    def _table_bytes(self, signals: tuple[SignalSpec, ...],
                     direct: set[int]) -> dict[int, list[SignalSpec]]:
        """Bytes (not part of a direct field) whose signals all lie within that byte: they are
        decoded through a 256-entry table instead of shifts and masks."""
        by_byte: dict[int, list[SignalSpec]] = {}
        spanning: set[int] = set()
        for sig in signals:
            first, last = sig.start // 8, (sig.start + sig.length - 1) // 8
            if first == last:
                by_byte.setdefault(first, []).append(sig)
            else:
                spanning.update(range(first, last + 1))
        return {b: sigs for b, sigs in by_byte.items()
                if b not in spanning and b not in direct and not any(s.is_float for s in sigs)}

    def _physical(self, sig: SignalSpec, raw: int) -> int | float:
        """cantools' raw -> physical arithmetic, as the generated code does it."""
        if sig.kind == "identity":
            return raw
        if sig.offset == 0 and sig.scale > 0:
            return raw * sig.scale
        return raw * sig.scale + sig.offset

    def _decode_layout(self, signals: tuple[SignalSpec, ...]) -> tuple[
            str, list[tuple[str, int, int]], dict[int, list[SignalSpec]]]:
        """The struct of ``decode``: the layout with the table bytes cut out as single ``B``
        fields (``t<byte>``); returns the format, the fields and the table bytes."""
        fmt, fields = self._layout(signals)
        direct_bytes = {b for name, first, width in fields if name.startswith("d")
                        for b in range(first // 8, (first + width) // 8)}
        tables = self._table_bytes(signals, direct_bytes)
        new_fmt = "<"
        new_fields: list[tuple[str, int, int]] = []
        for (name, first, width), code in zip(fields, fmt[1:], strict=True):
            if name.startswith("d"):
                new_fmt += code
                new_fields.append((name, first, width))
                continue
            pending: list[int] = []

            def flush(pending: list[int]) -> None:
                nonlocal new_fmt
                pos = 0
                while pos < len(pending):  # consecutive non-table bytes: widest pieces first
                    n = next(k for k in (8, 4, 2, 1) if pos + k <= len(pending))
                    new_fmt += {1: "B", 2: "H", 4: "I", 8: "Q"}[n]
                    new_fields.append((f"p{pending[pos]}", pending[pos] * 8, n * 8))
                    pos += n
                pending.clear()

            for b in range(first // 8, (first + width) // 8):
                if b in tables:
                    flush(pending)
                    new_fmt += "B"
                    new_fields.append((f"t{b}", b * 8, 8))
                else:
                    pending.append(b)
            flush(pending)
        return new_fmt, new_fields, tables

    def _decode_body(
        self, signals: tuple[SignalSpec, ...], fields: list[tuple[str, int, int]],
        tables: dict[int, list[SignalSpec]], tag: str, namespace: dict[str, Any],
        always_strict: bool,
    ) -> list[str]:
        """Lines (indented by 4) that decode ``signals`` from the unpacked ``fields`` and end
        in ``return {...}``; lookup tables go into ``namespace`` with the suffix ``tag``.
        ``always_strict``: the range checks without the test of a ``strict`` argument."""
        direct = {f[0] for f in fields if f[0].startswith("d")}
        pieces = [f for f in fields if f[0].startswith("p")]
        lines: list[str] = []
        table_var: dict[str, str] = {}
        for b, sigs in sorted(tables.items()):
            loose: list[tuple[int | float, ...]] = []
            valid: list[bool] = []
            for byte_value in range(256):
                row = []
                ok = True
                for sig in sigs:
                    raw = (byte_value >> (sig.start - 8 * b)) & sig.mask
                    if sig.is_signed and raw & (1 << (sig.length - 1)):
                        raw -= 1 << sig.length
                    ok = ok and sig.raw_min <= raw <= sig.raw_max
                    row.append(self._physical(sig, raw))
                loose.append(tuple(row))
                valid.append(ok)
            names = [f"s{self.signals.index(sig)}" for sig in sigs]
            for sig, var in zip(sigs, names, strict=True):
                table_var[sig.name] = var
            target = ", ".join(names)
            if len(sigs) == 1:  # a table of values, not of 1-tuples
                loose = [row[0] for row in loose]  # type: ignore[misc]
            namespace[f"_TL{b}{tag}"] = tuple(loose)
            if all(valid) and len(sigs) == 1:  # read once: inline in the result
                table_var[sigs[0].name] = f"_TL{b}{tag}[t{b}]"
            elif all(valid):
                lines.append(f"    {target} = _TL{b}{tag}[t{b}]")
            else:
                namespace[f"_TS{b}{tag}"] = tuple(r if ok else None for r, ok in
                                                   zip(loose, valid, strict=True))
                pick = (f"_TS{b}{tag}[t{b}]" if always_strict else
                        f"(_TS{b}{tag} if strict else _TL{b}{tag})[t{b}]")
                if len(sigs) == 1:
                    lines.append(f"    {target} = {pick}")
                    lines.append(f"    if {target} is None:")
                else:  # unpacking None (a signal out of range) raises: no test on the way
                    lines += ["    try:", f"        {target} = {pick}", "    except TypeError:"]
                lines.append("        _out_of_range(codec, decode_loose(data))")
        checks: list[str] = []
        out = []
        for s in signals:
            i = self.signals.index(s)
            if s.name in table_var:
                out.append(f"'{s.name}': {table_var[s.name]}")
                continue
            if (_direct_var(s) not in direct and not s.is_float and s.length <= _NARROW_BITS
                    and (s.is_signed or s.kind != "identity")):
                # a small field that needs sign or scale: its physical value from a table
                # indexed by its raw bits (None in the strict table: outside the range)
                loose_table, strict_table = _narrow_tables(self, s)
                namespace[f"_NL{i}"] = loose_table
                expr = self._piece_expr(s, pieces)
                if strict_table is None:
                    out.append(f"'{s.name}': _NL{i}[{expr}]")
                    continue
                namespace[f"_NS{i}"] = strict_table
                lines.append(f"    v{i} = _NS{i}[{expr}]" if always_strict else
                             f"    v{i} = (_NS{i} if strict else _NL{i})[{expr}]")
                lines.append(f"    if v{i} is None:")
                lines.append("        _out_of_range(codec, decode_loose(data))")
                out.append(f"'{s.name}': v{i}")
                continue
            full_lo = -(1 << (s.length - 1)) if s.is_signed else 0
            full_hi = (1 << (s.length - 1)) - 1 if s.is_signed else (1 << s.length) - 1
            needs_var = s.is_float or s.is_signed or (s.raw_min, s.raw_max) != (full_lo, full_hi)
            if _direct_var(s) in direct:
                v = str(_direct_var(s))
            elif not needs_var:
                v = f"({self._piece_expr(s, pieces)})"  # used once: inline in the result
            else:
                v = f"v{i}"
                lines.append(f"    {v} = {self._piece_expr(s, pieces)}")
                if s.is_float:
                    packer = "_F32" if s.length == 32 else "_F64"
                    lines.append(
                        f"    {v} = {packer}.unpack({v}.to_bytes({s.length // 8}, 'little'))[0]")
                elif s.is_signed:
                    lines.append(
                        f"    if {v} & {1 << (s.length - 1):#x}: {v} -= {1 << s.length:#x}")
            if s.is_float:
                checks.append(f"not ({s.minimum!r} <= {v} <= {s.maximum!r})")
                out.append(f"'{s.name}': {v}")
                continue
            if s.raw_min != full_lo:
                checks.append(f"{v} < {s.raw_min}")
            if s.raw_max != full_hi:
                checks.append(f"{v} > {s.raw_max}")
            if s.kind == "identity":
                out.append(f"'{s.name}': {v}")
            elif s.offset == 0 and s.scale > 0:
                # x + 0 == x for every x a positive scale can produce (no -0.0), so cantools'
                # ``raw * scale + offset`` reduces to the product; written ``scale * raw``
                # (the same IEEE product): float's multiply is then tried first, not int's
                out.append(f"'{s.name}': {s.scale!r} * {v}")
            else:
                out.append(f"'{s.name}': {s.scale!r} * {v} + {s.offset!r}")
        if checks:
            lines.append(f"    if {' or '.join(checks)}:" if always_strict else
                         f"    if strict and ({' or '.join(checks)}):")
            lines.append("        _out_of_range(codec, decode_loose(data))")
        lines.append("    return {" + ", ".join(out) + "}")
        return lines

    def _compile_decode(self) -> Callable[[bytes, bool], Signals]:
        """Generate ``decode(data, strict)``: one struct unpack; bytes of small bit fields
        through lookup tables; wider fields by shifts and masks. A multiplexed message unpacks
        once and branches on the multiplexer value to that value's signals."""
        cuts = [self._decode_layout(sigs) for sigs in self.signal_sets]
        fmt, fields, _ = cuts[0]
        if any((f, fl) != (fmt, fields) for f, fl, _ in cuts[1:]):
            raise TypeError(f"{self.name}: the multiplexed signal sets must share one byte "
                            "layout (same positions, widths and types)")
        namespace: dict[str, Any] = {
            "FrameLengthError": FrameLengthError,
            "_StructError": struct.error,
            "_F32": _F32,
            "_F64": _F64,
            "_unpack": struct.Struct(fmt).unpack,
            "_out_of_range": _out_of_range,
            "_unknown_mux": _unknown_mux,
            "codec": self,
        }

        def make_body(always_strict: bool) -> list[str]:
            if self.multiplexer is None:
                return self._decode_body(self.signals, fields, cuts[0][2], "", namespace,
                                         always_strict)
            body = [f"    mux = {self._raw_expr(self.multiplexer, fields)}"]
            # when the values cover every raw multiplexer value, the last needs no test
            every = len(self.variants) == 1 << self.multiplexer.length
            for n, ((k, sigs), (_, _, tables)) in enumerate(
                    zip(self.variants.items(), cuts, strict=True)):
                body.append("    if True:" if every and n == len(cuts) - 1 else
                            f"    if mux == {k}:")
                body += ["    " + ln for ln in self._decode_body(
                    sigs, fields, tables, f"_{k}", namespace, always_strict)]
            if not every:
                body.append("    _unknown_mux(codec, mux)")
            return body

        def named(body: list[str]) -> list[str]:
            return [ln.replace("return {", f"return '{self.name}', {{", 1)
                    if ln.lstrip().startswith("return {") else ln for ln in body]

        # the whole body in the try (only the unpack raises struct.error): no jump over the
        # handler on the way to the return
        unpack = (f"        {', '.join(f[0] for f in fields)}, = _unpack("
                  + ("bytes(data)[::-1])" if self.big_endian else "data)"))
        handler = [
            "    except _StructError:",
            f"        raise FrameLengthError('{self.name}: payload of %d bytes, the catalog "
            f"says {self.length}' % len(data)) from None",
        ]

        def function(head: str, body: list[str]) -> list[str]:
            return [head, "    try:", unpack, *("    " + ln for ln in body), *handler]

        # the same body returning (name, values), for Codec.decode; and both with the range
        # checks built in (strict=True, the default: one argument and its tests less)
        body, always = make_body(False), make_body(True)
        lines = [*function("def decode(data, strict):", body),
                 *function("def decode_named(data, strict):", named(body)),
                 *function("def decode_strict(data):", always),
                 *function("def decode_named_strict(data):", named(always))]
        self._decode_source = "\n".join(lines)
        exec(compile(self._decode_source, f"<lowerbase codec {self.name}.decode>", "exec"),
             namespace)
        decode = namespace["decode"]
        namespace["decode_loose"] = lambda data: decode(data, False)
        self._decode_named = namespace["decode_named"]
        self._decode_strict: Callable[[Payload], Signals] = namespace["decode_strict"]
        self._decode_named_strict: Callable[[Payload], tuple[str, Signals]] = (
            namespace["decode_named_strict"])
        return decode

    def _encode_body(self, signals: tuple[SignalSpec, ...], tag: str,
                     namespace: dict[str, Any]) -> list[str]:
        """Lines (indented by 4) that check and pack ``signals`` from ``values``."""
        fmt, fields = self._layout(signals)
        namespace[f"_S{tag}"] = struct.Struct(fmt)
        namespace[f"_N{tag}"] = frozenset(s.name for s in signals)
        index = {s.name: self.signals.index(s) for s in signals}
        lines = [
            f"    if len(values) != {len(signals)}:",
            f"        _keys(codec, values, _N{tag})",
            "    try:",
        ]
        lines += [f"        v{index[s.name]} = values['{s.name}']" for s in signals]
        lines += ["    except KeyError:", f"        _keys(codec, values, _N{tag})"]
        direct = {f[0] for f in fields if f[0].startswith("d")}
        for s in signals:
            v, r = f"v{index[s.name]}", f"r{index[s.name]}"
            lines.append(f"    if {v}.__class__ is not float and {v}.__class__ is not int:")
            lines.append(f"        {v} = _number(codec, '{s.name}', {v})")
            if s.is_float:
                lines.append(f"    if not ({s.minimum!r} <= {v} <= {s.maximum!r}):")
                lines.append(f"        _range(codec, '{s.name}', {v})")
                if _direct_var(s) not in direct:
                    packer = "_F32" if s.length == 32 else "_F64"
                    lines.append(f"    {r} = int.from_bytes({packer}.pack({v}), 'little')")
                else:
                    lines.append(f"    {r} = {v}")
                continue
            lines.append("    try:")
            if s.kind == "identity":
                lines.append(f"        {r} = {v} if {v}.__class__ is int else round({v})")
            elif s.kind == "int":
                lines.append(f"        q, m = divmod({v} - {s.offset!r}, {s.scale!r})")
                lines.append(
                    f"        {r} = round(q if m == 0 else ({v} - {s.offset!r}) / {s.scale!r})")
            elif s.offset == 0:
                lines.append(f"        {r} = round({v} / {s.scale!r})")
            else:
                lines.append(f"        {r} = round(({v} - {s.offset!r}) / {s.scale!r})")
            lines.append("    except (ValueError, OverflowError):")  # NaN, infinities
            lines.append(f"        _range(codec, '{s.name}', {v})")
            lines.append(f"    if {r} < {s.raw_min} or {r} > {s.raw_max}:")
            lines.append(f"        _range(codec, '{s.name}', {v})")
        args = []
        for name, first, width in fields:
            if name in direct:
                s = next(s for s in signals if _direct_var(s) == name)
                args.append(f"r{index[s.name]}")
                continue
            terms = []
            for s in signals:
                if _direct_var(s) in direct:
                    continue
                if s.start >= first + width or s.start + s.length <= first:
                    continue
                # the part of signal s that falls into this piece
                shift = s.start - first
                r = f"r{index[s.name]}"
                term = f"({r} & {s.mask:#x})" if s.is_signed or s.is_float else r
                terms.append(f"({term} << {shift})" if shift > 0 else
                             (f"({term} >> {-shift})" if shift < 0 else term))
            expr = " | ".join(terms) if terms else "0"
            args.append(f"({expr}) & {(1 << width) - 1:#x}")
        reverse = "[::-1]" if self.big_endian else ""
        lines.append(f"    return _S{tag}.pack({', '.join(args)}){reverse}")
        return lines

    def _compile_encode(self) -> Callable[[Mapping[str, Any]], bytes]:
        """Generate ``encode(values)``: cantools' rounding, raw range checks, one struct pack;
        a multiplexed message first branches on the multiplexer value."""
        namespace: dict[str, Any] = {
            "_F32": _F32,
            "_F64": _F64,
            "_number": _to_number,
            "_range": _range_error,
            "_keys": _keys_error,
            "_mux_error": _mux_error,
            "codec": self,
        }
        lines = ["def encode(values):"]
        mux = self.multiplexer
        if mux is None:
            lines += self._encode_body(self.signals, "", namespace)
        else:
            lines += [
                "    try:",
                f"        mux = values['{mux.name}']",
                "    except KeyError:",
                "        _mux_error(codec, None)",
                "    if mux.__class__ is not int:",
                f"        mux = _number(codec, '{mux.name}', mux)",
            ]
            for k, sigs in self.variants.items():
                lines.append(f"    if mux == {k}:")
                lines += ["    " + ln for ln in self._encode_body(sigs, f"_{k}", namespace)]
            lines.append("    _mux_error(codec, mux)")
        self._encode_source = "\n".join(lines)
        exec(compile(self._encode_source, f"<lowerbase codec {self.name}.encode>", "exec"),
             namespace)
        return namespace["encode"]

    def __repr__(self) -> str:
        return f"<MessageCodec {self.name} id={self.frame_id:#05x} dlc={self.length}>"


def _to_number(codec: MessageCodec, name: str, value: Any) -> int | float:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, str):
        return codec.choice_number(name, value)
    if isinstance(value, int):  # int subclasses (IntEnum, IntFlag)
        return int(value)
    if isinstance(value, float):
        return float(value)
    number = getattr(value, "value", None)  # cantools NamedSignalValue
    if isinstance(number, int):
        return number
    try:
        return float(value)
    except (TypeError, ValueError):
        raise EncodeError(
            f"{codec.name}.{name}: {value!r} is not a number or a choice name"
        ) from None


def _keys_error(codec: MessageCodec, values: Mapping[str, Any], names: frozenset[str]) -> None:
    missing = sorted(names - values.keys())
    unknown = sorted(set(values) - names)
    mux = codec.multiplexer
    raise EncodeError(
        f"{codec.name}: "
        + (f"{mux.name} = {values[mux.name]!r} selects " if mux and mux.name in values else "")
        + (f"missing signals {missing}" if missing else "")
        + ("; " if missing and unknown else "")
        + (f"unknown signals {unknown}" if unknown else "")
    )


def _mux_error(codec: MessageCodec, value: Any) -> NoReturn:
    """Encode: the multiplexer is missing, out of range or selects no signals."""
    mux = codec.multiplexer
    assert mux is not None
    if value is None:
        raise EncodeError(f"{codec.name}: missing the multiplexer signal {mux.name!r}")
    if not (mux.minimum <= value <= mux.maximum):  # NaN: False
        _range_error(codec, mux.name, value)
    raise EncodeError(f"{codec.name}: {mux.name} = {value!r} selects no signals (the catalog "
                      f"defines {sorted(codec.variants)})")


def _unknown_mux(codec: MessageCodec, value: int) -> NoReturn:
    """Decode: a multiplexer value that the catalog gives no signals."""
    mux = codec.multiplexer
    assert mux is not None
    raise ProtocolError(f"{codec.name}: {mux.name} = {value} selects no signals (the catalog "
                        f"defines {sorted(codec.variants)})")


def _out_of_range(codec: MessageCodec, values: Signals) -> None:
    """Raise for the first signal of a decoded payload that is outside its range."""
    for s in codec.signals:
        if s.name not in values:  # another multiplexer value's signal
            continue
        v = values[s.name]
        if not (s.minimum <= v <= s.maximum):  # type: ignore[operator]
            raise SignalRangeError(  # from None: raised while handling the unpack's TypeError
                f"{codec.name}.{s.name} = {v!r} is outside [{s.minimum}, {s.maximum}] {s.unit}"
                .rstrip()) from None
    raise AssertionError("no signal out of range")  # pragma: no cover


#: fields up to this width that need a sign or a scale decode through a table of 2**bits values
_NARROW_BITS = 12
_NARROW_CACHE: dict[tuple[Any, ...], tuple[tuple[Any, ...], tuple[Any, ...] | None]] = {}


def _narrow_tables(codec: MessageCodec, s: SignalSpec) -> tuple[
        tuple[int | float, ...], tuple[int | float | None, ...] | None]:
    """Raw bits -> physical value of a small field (the loose table), and the same with None
    outside the raw range (None when every value is in range); shared between equal fields."""
    key = (s.length, s.is_signed, s.kind, repr(s.scale), repr(s.offset), s.raw_min, s.raw_max)
    if key not in _NARROW_CACHE:
        loose, strict = [], []
        for bits in range(1 << s.length):
            raw = bits - (1 << s.length) if s.is_signed and bits >> (s.length - 1) else bits
            value = codec._physical(s, raw)
            loose.append(value)
            strict.append(value if s.raw_min <= raw <= s.raw_max else None)
        _NARROW_CACHE[key] = (tuple(loose), None if None not in strict else tuple(strict))
    return _NARROW_CACHE[key]


def _range_error(codec: MessageCodec, name: str, value: float) -> None:
    s = codec.signal(name)
    raise SignalRangeError(
        f"{codec.name}.{name} = {value!r} is outside [{s.minimum}, {s.maximum}] {s.unit}".rstrip()
    )


class Codec:
    """Every message of a DBC catalog, by name and by frame ID."""

    def __init__(self, dbc_path: str | Path = DBC_PATH) -> None:
        self.path = Path(dbc_path)
        database = cantools.database.load_file(str(self.path), strict=True)
        if not isinstance(database, cantools.database.can.Database):
            raise TypeError(f"{self.path} is not a CAN database")
        self.database = database
        self.messages: tuple[MessageCodec, ...] = tuple(
            MessageCodec(m) for m in sorted(self.database.messages, key=lambda m: m.frame_id)
        )
        self._by_name = {m.name: m for m in self.messages}
        self._by_id = {m.frame_id: m for m in self.messages}
        self._decoders = {m.frame_id: m._decode_named for m in self.messages}
        self._strict_decoders = {m.frame_id: m._decode_named_strict for m in self.messages}

    def __iter__(self) -> Iterator[MessageCodec]:
        return iter(self.messages)

    def __len__(self) -> int:
        return len(self.messages)

    def __contains__(self, key: object) -> bool:
        return key in self._by_name or key in self._by_id

    def message(self, key: str | int) -> MessageCodec:
        """The message with this name or frame ID."""
        found = self._by_name.get(key) if isinstance(key, str) else self._by_id.get(key)
        if found is None:
            what = repr(key) if isinstance(key, str) else f"ID {key:#05x}"
            raise UnknownMessageError(f"the catalog has no message {what}")
        return found

    def encode(self, name: str, values: Mapping[str, Any], *, strict: bool = True) -> bytes:
        msg = self._by_name.get(name)
        if msg is None or not strict:
            return self.message(name).encode(values, strict=strict)
        return msg._encode(values)

    def decoders(self) -> dict[int, Callable[[bytes, bool], tuple[str, Signals]]]:
        """Frame ID -> compiled ``decode(data, strict) -> (name, signals)``, for receive loops
        that dispatch on the ID themselves (one call less than :attr:`decode`)."""
        return dict(self._decoders)

    def _decode_slow(
        self, frame_id: int, data: bytes | bytearray | memoryview, decode_choices: bool,
        strict: bool,
    ) -> tuple[str, Signals]:
        msg = self._by_id.get(frame_id)
        if msg is None:
            raise UnknownMessageError(f"the catalog has no message with ID {frame_id:#05x}")
        return msg.name, msg.decode(data, decode_choices=decode_choices, strict=strict)

    def decode(
        self, frame_id: int, data: bytes | bytearray | memoryview,
        decode_choices: bool = False, strict: bool = True,
    ) -> tuple[str, Signals]:
        """Decode a frame; returns (message name, signals)."""
        # a method (CPython specializes the attribute lookup of a class's function, not of an
        # instance's) without keyword-only parameters (which leave the call unspecialized);
        # strict (the default) calls the decoder with the range checks built in. The compiled
        # decoders raise no KeyError: one here is an unknown ID (the slow path raises it typed)
        try:
            if strict and not decode_choices:
                return self._strict_decoders[frame_id](data)
            if not decode_choices:
                return self._decoders[frame_id](data, False)
        except KeyError:
            pass
        return self._decode_slow(frame_id, data, decode_choices, strict)


@cache
def default_codec() -> Codec:
    """The codec of the packaged ``chassis.dbc`` (built once per process)."""
    return Codec(DBC_PATH)
