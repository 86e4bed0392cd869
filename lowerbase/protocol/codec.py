"""A fast, strict codec compiled from the DBC catalog.

cantools parses ``chassis.dbc`` once; for every message, lowerbase.protocol.codegen then
generates plain Python functions (``encode``/``decode``) with the bit positions, masks, scales,
offsets and raw range limits inlined as constants, the way ``collections.namedtuple`` builds its
class.
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
from collections.abc import Callable, Iterator, Mapping
from functools import cache
from pathlib import Path
from typing import Any, Protocol

import cantools
from cantools.database.conversion import (
    IdentityConversion,
    LinearConversion,
    LinearIntegerConversion,
    NamedSignalConversion,
)

from lowerbase.errors import EncodeError, UnknownMessageError
from lowerbase.protocol.codec_errors import _mux_error, _to_number
from lowerbase.protocol.codegen import CodeGenerator
from lowerbase.protocol.signals import Signals, SignalSpec

DBC_PATH = Path(__file__).with_name("chassis.dbc")

class DecodeFunction(Protocol):
    def __call__(
        self, frame_id: int, data: bytes | bytearray | memoryview, *,
        decode_choices: bool = False, strict: bool = True,
    ) -> tuple[str, Signals]: ...



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


class MessageCodec(CodeGenerator):
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

    def __repr__(self) -> str:
        return f"<MessageCodec {self.name} id={self.frame_id:#05x} dlc={self.length}>"


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
