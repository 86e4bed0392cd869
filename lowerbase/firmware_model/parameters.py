"""Lower-computer parameters by index, their limits, and their persistent store.

Index numbers and names come from the catalog (the value table of ParameterRequest.Index);
units and ranges are the profile's (``ChassisParams`` field metadata), so a parameter file,
a profile and a ParameterRequest are checked against the same limits. The store writes the
parameter file atomically (temporary file,
fsync, rename), so a crash mid-write leaves the previous file intact.
"""

from __future__ import annotations

import enum
import json
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from lowerbase.files import remove_stale_temps, write_atomic
from lowerbase.protocol.codec import default_codec

log = logging.getLogger(__name__)


class Result(enum.IntEnum):
    """ParameterResponse.Result (the catalog's value table)."""

    ACK = 0
    UNKNOWN_INDEX = 1
    OUT_OF_RANGE = 2
    READ_ONLY = 3
    NOT_ALLOWED_NOW = 4
    STORAGE_ERROR = 5
    INVALID_VALUE = 6
    BAD_REQUEST = 7


@dataclass(frozen=True)
class ParameterSpec:
    index: int
    name: str  #: woosh_msgs/Parameter field name (camelCase), as in the catalog
    unit: str
    minimum: float
    maximum: float
    integer: bool = False
    #: geometry and gearing cannot change while the wheels turn (odometry would jump)
    only_at_rest: bool = False


#: geometry and gearing cannot change while the wheels turn (odometry would jump)
_ONLY_AT_REST = frozenset(
    {"wheelPerimeter", "wheelDistant", "ratioLeft", "ratioRight", "pulsePerCircle"}
)


def _specs() -> dict[int, ParameterSpec]:
    """Index and name from the catalog; unit and range from the profile's ChassisParams."""
    from lowerbase.firmware_model.profile import CHASSIS_WIRE_NAMES, ChassisParams

    meta = {f.name: f.metadata for f in fields(ChassisParams)}
    choices = default_codec().message("ParameterRequest").signal("Index").choices
    specs = {}
    for index, name in choices.items():
        m = meta[CHASSIS_WIRE_NAMES[name]]
        lo, hi = m["range"]
        specs[index] = ParameterSpec(
            index, name, m["unit"], float(lo), float(hi), bool(m["integer"]),
            name in _ONLY_AT_REST,
        )
    missing = set(CHASSIS_WIRE_NAMES) - {s.name for s in specs.values()}
    if missing:  # pragma: no cover - guards the catalog against the profile
        raise RuntimeError(f"parameters without an index in the catalog: {sorted(missing)}")
    return specs


SPECS: dict[int, ParameterSpec] = _specs()
BY_NAME: dict[str, ParameterSpec] = {s.name: s for s in SPECS.values()}


def check(spec: ParameterSpec, value: float) -> Result:
    """Whether ``value`` may be written to ``spec`` (range, finiteness, integrality)."""
    if not math.isfinite(value):
        return Result.INVALID_VALUE
    if spec.integer and value != round(value):
        return Result.INVALID_VALUE
    if not spec.minimum <= value <= spec.maximum:
        return Result.OUT_OF_RANGE
    return Result.ACK


def write_json_atomic(path: Path, data: Mapping[str, Any]) -> None:
    """Write JSON so that readers and a crash mid-write only ever see a whole file."""
    write_atomic(path, json.dumps(data, indent=2, sort_keys=True) + "\n")


class ParameterStore:
    """The parameter file: ``{"parameters": {name: value}, "boot_counter": n, "odometer": m}``.

    Without a path everything lives in memory (nothing persists), as on a board without flash.
    """

    def __init__(self, path: str | Path | None) -> None:
        self.path = Path(path) if path else None
        if self.path is not None:  # a crash mid-write leaves its temporary file: clean it up
            for tmp in remove_stale_temps(self.path):
                log.warning("removed %s, left by an interrupted write", tmp)

    def load(self) -> tuple[dict[str, float], dict[str, Any], list[str]]:
        """(parameters, state, problems). Problems name what was unreadable or invalid."""
        if self.path is None or not self.path.exists():
            return {}, {}, []
        try:
            raw = json.loads(self.path.read_text(encoding="utf-8"))
            if not isinstance(raw, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as exc:
            return {}, {}, [f"{self.path}: unreadable ({exc}); defaults used"]
        problems = []
        params: dict[str, float] = {}
        for name, value in dict(raw.get("parameters", {})).items():
            spec = BY_NAME.get(name)
            if spec is None:
                problems.append(f"{self.path}: unknown parameter {name!r} ignored")
                continue
            if not isinstance(value, (int, float)) or check(spec, float(value)) != Result.ACK:
                problems.append(f"{self.path}: {name}={value!r} invalid; default used")
                continue
            params[name] = float(value)
        state = {k: v for k, v in raw.items() if k != "parameters"}
        return params, state, problems

    def save(self, params: Mapping[str, float], state: Mapping[str, Any]) -> None:
        if self.path is None:
            return
        write_json_atomic(self.path, {"parameters": dict(params), **state})
