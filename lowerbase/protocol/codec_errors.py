"""What the compiled codec calls on the way to a typed error (lowerbase.protocol.codegen writes
the calls into the generated functions; MessageCodec uses the number conversion too)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NoReturn

from lowerbase.errors import EncodeError, ProtocolError, SignalRangeError
from lowerbase.protocol.signals import MessageSpec, Signals


def _to_number(codec: MessageSpec, name: str, value: Any) -> int | float:
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


def _keys_error(codec: MessageSpec, values: Mapping[str, Any], names: frozenset[str]) -> None:
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


def _mux_error(codec: MessageSpec, value: Any) -> NoReturn:
    """Encode: the multiplexer is missing, out of range or selects no signals."""
    mux = codec.multiplexer
    assert mux is not None
    if value is None:
        raise EncodeError(f"{codec.name}: missing the multiplexer signal {mux.name!r}")
    if not (mux.minimum <= value <= mux.maximum):  # NaN: False
        _range_error(codec, mux.name, value)
    raise EncodeError(f"{codec.name}: {mux.name} = {value!r} selects no signals (the catalog "
                      f"defines {sorted(codec.variants)})")


def _unknown_mux(codec: MessageSpec, value: int) -> NoReturn:
    """Decode: a multiplexer value that the catalog gives no signals."""
    mux = codec.multiplexer
    assert mux is not None
    raise ProtocolError(f"{codec.name}: {mux.name} = {value} selects no signals (the catalog "
                        f"defines {sorted(codec.variants)})")


def _out_of_range(codec: MessageSpec, values: Signals) -> None:
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


def _range_error(codec: MessageSpec, name: str, value: float) -> None:
    s = codec.signal(name)
    raise SignalRangeError(
        f"{codec.name}.{name} = {value!r} is outside [{s.minimum}, {s.maximum}] {s.unit}".rstrip()
    )
