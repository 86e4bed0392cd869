"""Code generation for the compiled codec (lowerbase.protocol.codec).

For one catalog message, ``CodeGenerator`` writes plain Python functions with the bit
positions, masks, scales, offsets and raw range limits inlined as constants and compiles them
with ``exec``: ``decode(data, strict)`` and ``decode_named`` (returning (name, values)), the
same two with the range checks built in (``decode_strict(data)``, ``decode_named_strict``:
what strict decoding, the default, calls), and ``encode(values)``. Decoding is one struct
unpack; bytes of small bit fields and small fields that need a sign or a scale read their
values from tables; wider fields are shifted and masked.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from lowerbase.errors import FrameLengthError
from lowerbase.protocol.codec_errors import (
    _keys_error,
    _mux_error,
    _out_of_range,
    _range_error,
    _to_number,
    _unknown_mux,
)

if TYPE_CHECKING:
    from lowerbase.protocol.signals import Payload, Signals, SignalSpec


_F32 = struct.Struct("<f")
_F64 = struct.Struct("<d")


def _direct_var(s: SignalSpec) -> str | None:
    """The struct field of a signal that fills whole, aligned bytes of size 1, 2, 4 or 8."""
    return f"d{s.start // 8}" if s.start % 8 == 0 and s.length in (8, 16, 32, 64) else None


class CodeGenerator:
    """The code generation half of :class:`~lowerbase.protocol.codec.MessageCodec`."""

    name: str
    length: int
    big_endian: bool
    signals: tuple[SignalSpec, ...]
    variants: dict[int, tuple[SignalSpec, ...]]
    multiplexer: SignalSpec | None

    @property
    def signal_sets(self) -> tuple[tuple[SignalSpec, ...], ...]:
        """The signal sets a frame can carry: one per multiplexer value, or all signals."""
        return tuple(self.variants.values()) or (self.signals,)

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



#: fields up to this width that need a sign or a scale decode through a table of 2**bits values
_NARROW_BITS = 12
_NARROW_CACHE: dict[tuple[Any, ...], tuple[tuple[Any, ...], tuple[Any, ...] | None]] = {}


def _narrow_tables(codec: CodeGenerator, s: SignalSpec) -> tuple[
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
