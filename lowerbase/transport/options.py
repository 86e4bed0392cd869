"""``--bus-kwargs`` checked against the chosen interface before a bus is opened.

python-can passes ``--bus-kwargs`` straight to the bus class, whose ``**kwargs`` swallow any
misspelt key (``porto=43114`` silently leaves the user on the default, shared port), and turns a
value of the wrong type into a traceback deep inside ``can.util``. Here every key must be one the
interface's bus class names (its constructor's parameters, or a ``kwargs["key"]`` /
``kwargs.get("key")`` it reads), with a did-you-mean for near misses; values are converted to the
parameter's declared type (int, float, bool, str) or refused with a one-line :class:`ConfigError`.
"""

from __future__ import annotations

import argparse
import difflib
import inspect
import logging
import re
from typing import Any

import can

from lowerbase.errors import ConfigError

log = logging.getLogger(__name__)

#: keys can.Bus() itself consumes, whatever the interface
_FACTORY_KEYS = frozenset({"interface", "channel", "context", "config_context", "ignore_config"})
#: a key a bus class reads out of its ``**kwargs`` in its own source
_KWARGS_READ = re.compile(r"kwargs(?:\.get|\.pop|\.setdefault)?[(\[]\s*[\"'](\w+)[\"']")
_SIMPLE_TYPES: dict[str, type] = {"int": int, "float": float, "bool": bool, "str": str}


def bus_class(interface: str) -> type[can.BusABC] | None:
    """The python-can bus class of ``interface``; None when it cannot be imported here (a
    vendor library missing): then opening the bus reports the real problem."""
    from can.interface import _get_class_for_interface

    try:
        return _get_class_for_interface(interface)
    except (NotImplementedError, ImportError, AttributeError) as exc:
        log.debug("cannot check --bus-kwargs for %s: %s", interface, exc)
        return None


def _params(cls: type) -> dict[str, inspect.Parameter]:
    """Named constructor parameters of ``cls`` and of its bus base classes."""
    params: dict[str, inspect.Parameter] = {}
    for klass in reversed(cls.__mro__):
        if not (isinstance(klass, type) and issubclass(klass, can.BusABC)):
            continue
        try:
            sig = inspect.signature(klass.__init__)
        except (TypeError, ValueError):
            continue
        for name, p in sig.parameters.items():
            if name != "self" and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
                params[name] = p
    return params


def _kwargs_read(cls: type) -> set[str]:
    """Keys the bus class (or a bus base class) reads from ``**kwargs`` in its source."""
    keys: set[str] = set()
    for klass in cls.__mro__:
        if isinstance(klass, type) and issubclass(klass, can.BusABC) and klass is not object:
            try:
                keys.update(_KWARGS_READ.findall(inspect.getsource(klass)))
            except (OSError, TypeError):
                continue
    return keys


def known_keys(cls: type) -> set[str]:
    """Every keyword the bus class accepts and uses."""
    return set(_params(cls)) | _kwargs_read(cls) | _FACTORY_KEYS


def _declared_type(p: inspect.Parameter) -> type | None:
    """int/float/bool/str from the default value or the annotation, else None (unchecked)."""
    if p.default is not inspect.Parameter.empty and type(p.default) in (bool, int, float, str):
        return type(p.default)
    ann = p.annotation
    text = ann if isinstance(ann, str) else getattr(ann, "__name__", "")
    text = re.sub(r"^Optional\[(.*)\]$", r"\1", text.replace(" ", ""))
    text = re.sub(r"\|None$|^None\|", "", text)
    return _SIMPLE_TYPES.get(text)


def _convert(interface: str, key: str, value: Any, want: type | None) -> Any:
    def refuse(what: str) -> ConfigError:
        return ConfigError(f"--bus-kwargs {key}={value}: {interface}'s {key} must be {what}")

    if want is None:
        return value
    if want is bool:
        if isinstance(value, bool):
            return value
        raise refuse("true or false")
    if want is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise refuse("an integer")
    if want is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise refuse("a number")
    return value if isinstance(value, str) else str(value)


_FILTER = re.compile(r"^([0-9A-Fa-f]{1,8})([:~])([0-9A-Fa-f]{1,8})$")


def _can_filters(value: Any) -> list[dict[str, Any]]:
    """``can_filters`` from the command line: hex ID:MASK (or ID~MASK: all but those) pairs
    separated by commas, as python-can's ``--filter`` takes them."""
    if isinstance(value, list):
        return value
    filters = []
    for part in str(value).split(","):
        m = _FILTER.match(part.strip())
        if m is None:
            raise ConfigError(f"--bus-kwargs can_filters={value}: expected hex ID:MASK pairs "
                              "separated by commas, e.g. can_filters=100:7FF,200:7F0")
        can_id, mask = int(m[1], 16), int(m[3], 16)
        if m[2] == "~":
            can_id |= 0x20000000  # CAN_INV_FILTER, as python-can's --filter
        filters.append({"can_id": can_id, "can_mask": mask})
    return filters


class BusKwargsAction(argparse.Action):
    """python-can's ``--bus-kwargs key=value ...``, but a key given twice (also across
    repeated flags) is refused instead of the last one silently winning."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        from can.util import cast_from_string

        kwargs: dict[str, Any] = dict(getattr(namespace, self.dest, None) or {})
        for arg in values if isinstance(values, list) else [values]:
            m = re.match(r"^(?P<name>[_a-zA-Z][-_a-zA-Z0-9]*)=(?P<value>\S*?)$", str(arg))
            if m is None:
                raise argparse.ArgumentError(self, f"{arg!r} is not KEY=VALUE")
            key = m["name"].replace("-", "_")
            if key in kwargs:
                raise argparse.ArgumentError(self, f"{key} given twice")
            kwargs[key] = cast_from_string(m["value"])
        setattr(namespace, self.dest, kwargs)


def use_strict_bus_kwargs(parser: argparse.ArgumentParser) -> None:
    """Make ``parser``'s ``--bus-kwargs`` a :class:`BusKwargsAction` (after python-can's
    ``add_bus_arguments``)."""
    for action in parser._actions:
        if action.dest == "bus_kwargs":
            action.__class__ = BusKwargsAction


def check_bus_kwargs(interface: str, bus_kwargs: dict[str, Any]) -> dict[str, Any]:
    """``bus_kwargs`` with values of the declared types; ConfigError for an unknown key (with a
    did-you-mean) or a value of the wrong type."""
    cls = bus_class(interface)
    if cls is None or not bus_kwargs:
        return dict(bus_kwargs)
    params = _params(cls)
    known = known_keys(cls)
    checked: dict[str, Any] = {}
    for key, value in bus_kwargs.items():
        if key not in known:
            close = difflib.get_close_matches(key, sorted(known - _FACTORY_KEYS), n=1)
            hint = f"did you mean {close[0]!r}? " if close else ""
            options = ", ".join(sorted(known - _FACTORY_KEYS))
            raise ConfigError(f"--bus-kwargs: {interface} has no option {key!r}; {hint}"
                              f"its options: {options}")
        if key == "can_filters":
            checked[key] = _can_filters(value)
            continue
        p = params.get(key)
        checked[key] = _convert(interface, key, value, _declared_type(p) if p else None)
        if key == "port" and isinstance(checked[key], int) and not 1 <= checked[key] <= 65535:
            raise ConfigError(f"--bus-kwargs port={value}: {interface}'s port must be "
                              "1-65535")
    return checked


def checked_config(interface: str | None, channel: Any, extra: dict[str, Any],
                   bus_kwargs: dict[str, Any]) -> dict[str, Any]:
    """The bus configuration of the command-line flags (``extra``: -b, --fd, ...) and
    ``--bus-kwargs``, checked against the interface they resolve to."""
    from lowerbase.transport.config import bus_config

    def resolve(kwargs: dict[str, Any]) -> dict[str, Any]:
        try:
            config = bus_config(interface, channel, **kwargs)
            # once more with the interface named: python-can checks (port range, state...)
            # only then, and open_bus() resolves the same way
            return bus_config(**config)
        except (ValueError, TypeError) as exc:
            raise ConfigError(f"bus options: {exc}") from None

    if bus_kwargs:
        resolved = resolve(extra)["interface"]
        bus_kwargs = check_bus_kwargs(str(resolved), bus_kwargs)
    return resolve({**extra, **bus_kwargs})

__all__ = ["bus_class", "check_bus_kwargs", "checked_config", "known_keys"]
