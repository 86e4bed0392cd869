"""A TOML table being validated: typed getters, unknown keys reported with a suggestion; each
error one line naming the item and the problem (every scenario kind's loader uses it)."""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from typing import Any

from lowerbase.errors import ConfigError


class Table:
    """A TOML table being validated: typed getters, unknown keys reported with a suggestion."""

    def __init__(self, data: Any, where: str) -> None:
        if not isinstance(data, Mapping):
            raise ConfigError(f"{where} must be a table, not {data!r}")
        self.data = data
        self.where = where
        self.used: set[str] = set()

    def _get(self, key: str) -> Any:
        self.used.add(key)
        return self.data.get(key)

    def has(self, key: str) -> bool:
        return key in self.data

    def number(self, key: str, default: float | None = None, *, lo: float = -math.inf,
               hi: float = math.inf, required: bool = False) -> float:
        value = self._get(key)
        if value is None:
            if required or default is None:
                raise ConfigError(f"{self.where}: missing {key}")
            return default
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{self.where}: {key} must be a number, not {value!r}")
        if not (math.isfinite(value) and lo <= value <= hi):
            raise ConfigError(f"{self.where}: {key} = {value!r} is outside {lo:g}..{hi:g}")
        return float(value)

    def opt_number(self, key: str, *, lo: float = -math.inf, hi: float = math.inf
                   ) -> float | None:
        return self.number(key, lo=lo, hi=hi) if self.has(key) else None

    def text(self, key: str, default: str | None = None, *,
             choices: Sequence[str] | None = None) -> str:
        value = self._get(key)
        if value is None:
            if default is None:
                raise ConfigError(f"{self.where}: missing {key}")
            return default
        if not isinstance(value, str):
            raise ConfigError(f"{self.where}: {key} must be a string, not {value!r}")
        if choices is not None and value not in choices:
            close = difflib.get_close_matches(value, list(choices), n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"one of: {', '.join(choices)}"
            raise ConfigError(f"{self.where}: {key} = {value!r} is not known; {hint}")
        return value

    def flag(self, key: str, default: bool) -> bool:
        value = self._get(key)
        if value is None:
            return default
        if not isinstance(value, bool):
            raise ConfigError(f"{self.where}: {key} must be true or false, not {value!r}")
        return value

    def interval(self, key: str) -> tuple[float, float] | None:
        value = self._get(key)
        if value is None:
            return None
        if (not isinstance(value, list) or len(value) != 2 or any(
                isinstance(v, bool) or not isinstance(v, int | float) for v in value)
                or not value[0] <= value[1]):
            raise ConfigError(f"{self.where}: {key} must be [start, end] in seconds with "
                              f"start <= end, not {value!r}")
        return float(value[0]), float(value[1])

    def integer_or_name(self, key: str, default: int, names: Mapping[str, int],
                        lo: int, hi: int) -> int:
        value = self._get(key)
        if value is None:
            return default
        if isinstance(value, str):
            lookup = {k.lower(): v for k, v in names.items()}
            if value.lower() in lookup:
                return lookup[value.lower()]
            if value.startswith("#") and len(value) == 7:
                try:
                    return int(value[1:], 16)
                except ValueError:
                    pass
            raise ConfigError(f"{self.where}: {key} = {value!r} is not known; "
                              f"one of: {', '.join(names) or 'a number'}")
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise ConfigError(f"{self.where}: {key} must be an integer {lo}..{hi}, not {value!r}")
        return value

    def done(self, allowed: set[str] | None = None) -> None:
        """Reject keys nobody asked for."""
        known = sorted(allowed if allowed is not None else self.used)
        for key in self.data:
            if key not in known:
                close = difflib.get_close_matches(key, known, n=1)
                hint = f"; did you mean {close[0]}?" if close else f"; known: {', '.join(known)}"
                raise ConfigError(f"{self.where}: unknown key {key!r}{hint}")
