"""A small TOML writer for what TOML files parse into (tables, arrays of tables, scalars,
arrays of scalars): enough to write a run's varied profile and scenario back out."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

from lowerbase.errors import CampaignError


def _key(k: str) -> str:
    bare = k and all(c.isalnum() or c in "_-" for c in k)
    return k if bare else json.dumps(k)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_key(str(k))} = {_value(x)}" for k, x in v.items()) + "}"
    raise CampaignError(f"cannot write {v!r} ({type(v).__name__}) as TOML")


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, Mapping) for x in v)


def _emit(table: Mapping[str, Any], prefix: str, lines: list[str]) -> None:
    for k, v in table.items():
        if not isinstance(v, Mapping) and not _is_table_array(v):
            lines.append(f"{_key(str(k))} = {_value(v)}")
    for k, v in table.items():
        name = f"{prefix}{_key(str(k))}"
        if isinstance(v, Mapping):
            lines += ["", f"[{name}]"]
            _emit(v, f"{name}.", lines)
        elif _is_table_array(v):
            for item in v:
                lines += ["", f"[[{name}]]"]
                _emit(item, f"{name}.", lines)


def dumps(doc: Mapping[str, Any]) -> str:
    """``doc`` as TOML text that ``tomllib.loads`` reads back equal."""
    lines: list[str] = []
    _emit(doc, "", lines)
    return "\n".join(lines).lstrip("\n") + "\n"
