"""Named places of a map, in a sidecar next to it: ``<map>.places.yaml``.

::

    charger:                       # the charging station
      pose: [3.3, 1.0, -1.570796]  # docked (x [m], y [m], yaw [rad], map frame)
      approach: [3.3, 2.0, -1.570796]  # where the docking manoeuvre starts
    storage:                       # storage points by mark_no (strings, as ExecTask's mark_no)
      "A1-01": [9.5, 4.75, 0.0]
    poses:                         # any other named pose
      start: [4.0, 4.0, 0.0]

Every section is optional. :func:`load_places` checks each place against its map: inside it,
and the robot's footprint there on free floor.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from lowerbase.errors import LowerbaseError, MapError
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, Footprint, Pose, validate_pose
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.maps import read_map, resolve_map

SUFFIX = ".places.yaml"


@dataclass(frozen=True)
class Charger:
    pose: Pose
    approach: Pose


@dataclass(frozen=True)
class Places:
    """A map's named places: storage points by mark_no, the charger, other named poses."""

    storage: dict[str, Pose] = field(default_factory=dict)
    charger: Charger | None = None
    poses: dict[str, Pose] = field(default_factory=dict)

    def named(self) -> dict[str, Pose]:
        """Every place by name: mark_nos, ``charger``, ``charger_approach``, other poses."""
        out = dict(self.storage)
        if self.charger is not None:
            out["charger"] = self.charger.pose
            out["charger_approach"] = self.charger.approach
        out.update(self.poses)
        return out

    def pose(self, name: str) -> Pose:
        """The pose of a place by name; :class:`MapError` naming the known places if unknown."""
        named = self.named()
        if name not in named:
            known = ", ".join(sorted(named)) or "none"
            raise MapError(f"unknown place {name!r}: this map has {known}")
        return named[name]


def places_path(map_yaml: Path | str) -> Path:
    """The sidecar of a map YAML: ``warehouse.yaml`` -> ``warehouse.places.yaml``."""
    map_yaml = Path(map_yaml)
    return map_yaml.with_name(map_yaml.stem + SUFFIX)


def _pose(value: Any, where: str) -> Pose:
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) for v in value)):
        raise MapError(f"{where} must be [x, y, yaw] (finite numbers), got {value!r}")
    return float(value[0]), float(value[1]), float(value[2])


def _named_poses(doc: dict[str, Any], key: str, where: Path) -> dict[str, Pose]:
    section = doc.get(key) or {}
    if not isinstance(section, dict):
        raise MapError(f"{where}: '{key}' must be a mapping of name: [x, y, yaw]")
    out = {}
    for name, value in section.items():
        if not isinstance(name, str) or not name.strip() or "\n" in name:
            raise MapError(f"{where}: {key} names are non-empty strings, got {name!r} "
                           f"(quote it: \"{name}\")")
        out[name] = _pose(value, f"{where}: {key} {name!r}")
    return out


def parse_places(doc: Any, where: Path) -> Places:
    """Places from a parsed sidecar document."""
    if doc is None:
        return Places()
    if not isinstance(doc, dict):
        raise MapError(f"{where}: a places file is a mapping (charger, storage, poses)")
    unknown = sorted(set(doc) - {"charger", "storage", "poses"})
    if unknown:
        raise MapError(f"{where}: unknown section(s) {', '.join(map(str, unknown))} "
                       "(use charger, storage, poses)")
    charger = None
    if doc.get("charger") is not None:
        ch = doc["charger"]
        if not isinstance(ch, dict) or set(ch) != {"pose", "approach"}:
            raise MapError(f"{where}: 'charger' needs exactly pose and approach")
        charger = Charger(_pose(ch["pose"], f"{where}: charger pose"),
                          _pose(ch["approach"], f"{where}: charger approach"))
    storage = _named_poses(doc, "storage", where)
    poses = _named_poses(doc, "poses", where)
    clash = sorted((set(storage) | {"charger", "charger_approach"}) & set(poses))
    if clash:
        raise MapError(f"{where}: {', '.join(clash)} named twice (storage/charger and poses)")
    return Places(storage, charger, poses)


def read_places(path: Path | str) -> Places:
    """Read a sidecar file (no checks against the map)."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MapError(f"places file {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MapError(f"cannot read places file {path}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" (line {mark.line + 1})" if mark is not None else ""
        raise MapError(f"{path}: not valid YAML{at}") from None
    return parse_places(doc, path)


def validate_places(places: Places, grid: OccupancyGrid,
                    footprint: Footprint = DEFAULT_FOOTPRINT, where: str = "") -> None:
    """:class:`MapError` (one line) if a place's footprint leaves the map or touches a wall."""
    prefix = f"{where}: " if where else ""
    for name, pose in places.named().items():
        try:
            validate_pose(pose, grid, footprint=footprint, what=f"place {name!r}")
        except LowerbaseError as exc:
            raise MapError(f"{prefix}{exc}") from None


def load_places(name_or_path: str | Path, grid: OccupancyGrid | None = None,
                footprint: Footprint = DEFAULT_FOOTPRINT) -> Places:
    """The places of a shipped map (by name) or of a map YAML, checked against the map.

    A map without a sidecar has no places.
    """
    map_yaml = resolve_map(name_or_path)
    sidecar = places_path(map_yaml)
    if not sidecar.exists():
        return Places()
    places = read_places(sidecar)
    validate_places(places, grid if grid is not None else read_map(map_yaml), footprint,
                    str(sidecar))
    return places


def format_places(places: Places, title: str = "") -> str:
    """Deterministic sidecar text (poses to 6 decimals)."""
    def pose(p: Pose) -> str:
        return "[" + ", ".join(repr(round(v, 6) + 0.0) for v in p) + "]"

    lines = [f"# {title}"] if title else []
    if places.charger is not None:
        lines += ["charger:", f"  pose: {pose(places.charger.pose)}",
                  f"  approach: {pose(places.charger.approach)}"]
    for key, section in (("storage", places.storage), ("poses", places.poses)):
        if section:
            lines.append(f"{key}:")
            lines += [f"  {json.dumps(name)}: {pose(p)}" for name, p in section.items()]
    return "\n".join(lines) + "\n"


def write_places(places: Places, path: Path | str, title: str = "") -> Path:
    path = Path(path)
    try:
        path.write_text(format_places(places, title), encoding="utf-8")
    except OSError as exc:
        raise MapError(f"cannot write places file {path}: {exc}") from None
    return path
