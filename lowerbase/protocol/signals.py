"""The catalog's signals as values and specs: what the codec, its code generator and its error
paths share (below all three, so none of them imports another for its types)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

SignalValue = int | float | str
Signals = dict[str, SignalValue]
Payload = bytes | bytearray | memoryview


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


class MessageSpec(Protocol):
    """What the error paths read of a message's codec (:class:`~lowerbase.protocol.codec.
    MessageCodec`)."""

    name: str
    signals: tuple[SignalSpec, ...]
    variants: dict[int, tuple[SignalSpec, ...]]
    multiplexer: SignalSpec | None

    def signal(self, name: str) -> SignalSpec: ...

    def choice_number(self, signal: str, name: str) -> int: ...
