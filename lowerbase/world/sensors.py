"""The robot profile's ``[sensors]`` section: the lidars, the merged /scan and the depth camera.

In the TOML, angles are in degrees (``*_deg``) and everything else in SI units::

    [sensors.scan]            # the fused /scan in base_link
    beams = 720
    [[sensors.lidar]]         # one table per lidar (LidarConfig fields; yaw_deg, fov_deg, ...)
    name = "front"
    x = 0.34
    [sensors.camera]          # CameraConfig fields; yaw_deg, pitch_deg

A missing section or key takes the default (two SICK nanoScan3 at diagonal corners, one
RealSense D435 at the front; docs/world.md, "Sensors"). Unknown keys are refused with one
ConfigError line; a sensor mounted outside the robot's footprint is one WorldError line.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from shapely.geometry import Point

from lowerbase.errors import ConfigError, WorldError
from lowerbase.files import read_toml
from lowerbase.world.camera import CameraConfig
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, Footprint
from lowerbase.world.lidar import LidarConfig, MergedScanConfig

#: SICK nanoScan3 pair on the diagonal corners (each 275 deg, together the full circle)
DEFAULT_LIDARS = (
    LidarConfig(name="front", frame_id="laser_front", x=0.34, y=0.24, yaw=math.radians(45),
                seed=1),
    LidarConfig(name="back", frame_id="laser_back", x=-0.34, y=-0.24, yaw=math.radians(-135),
                seed=2),
)

_DEGREES = {"yaw_deg": "yaw", "fov_deg": "fov", "angular_step_deg": "angular_step",
            "pitch_deg": "pitch", "angle_min_deg": "angle_min"}


@dataclass(frozen=True)
class SensorsConfig:
    lidars: tuple[LidarConfig, ...] = DEFAULT_LIDARS
    scan: MergedScanConfig = field(default_factory=MergedScanConfig)
    camera: CameraConfig | None = field(default_factory=CameraConfig)

    def check_mounts(self, footprint: Footprint = DEFAULT_FOOTPRINT) -> None:
        """WorldError unless every sensor sits on the base (inside or on the footprint)."""
        mounts: list[tuple[str, float, float]] = [(f"lidar {lc.name!r}", lc.x, lc.y)
                                                  for lc in self.lidars]
        if self.camera is not None:
            mounts.append((f"camera {self.camera.name!r}", self.camera.x, self.camera.y))
        region = footprint.polygon.buffer(1e-6)
        for what, x, y in mounts:
            if not region.covers(Point(x, y)):
                raise WorldError(f"{what} at ({x:g}, {y:g}) m is outside the robot's footprint; "
                                 f"mount it on the base (x, y inside the footprint polygon)")


def _table(section: str, data: Mapping[str, Any], known: Sequence[str]) -> dict[str, Any]:
    if not isinstance(data, Mapping):
        raise ConfigError(f"[{section}] must be a table, not {data!r}")
    out: dict[str, Any] = {}
    for key, value in data.items():
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1)
            hint = f"did you mean {section}.{close[0]}?" if close else f"known: {', '.join(known)}"
            raise ConfigError(f"unknown key {section}.{key}; {hint}")
        if key in _DEGREES:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f"{section}.{key} = {value!r} is not a number")
            out[_DEGREES[key]] = math.radians(value)
        else:
            out[key] = value
    return out


def _keys(cls: type) -> list[str]:
    back = {v: k for k, v in _DEGREES.items()}
    return [back.get(f.name, f.name) for f in fields(cls)]


def _build(cls: type, section: str, table: Mapping[str, Any]) -> Any:
    try:
        return cls(**_table(section, table, _keys(cls)))
    except TypeError as e:  # a wrongly typed value reaching arithmetic in validation
        raise ConfigError(f"[{section}] has a value of the wrong type: {e}") from None


def sensors_from_dict(data: Mapping[str, Any], source: str = "<dict>") -> SensorsConfig:
    """A SensorsConfig from the ``[sensors]`` table; ConfigError messages start with source."""
    try:
        top = _table("sensors", data, ["scan", "lidar", "camera"])
        scan = _build(MergedScanConfig, "sensors.scan", top.get("scan", {}))
        lidars = DEFAULT_LIDARS
        if "lidar" in top:
            raw = top["lidar"]
            if not isinstance(raw, list) or not raw:
                raise ConfigError("[[sensors.lidar]] must be one or more tables")
            lidars = tuple(_build(LidarConfig, f"sensors.lidar[{i}]", t)
                           for i, t in enumerate(raw))
            names = [lc.name for lc in lidars]
            if len(set(names)) != len(names):
                raise ConfigError(f"sensors.lidar names must be unique, got {names}")
        camera_table = top.get("camera", {})
        enabled = camera_table.get("enabled", True) if isinstance(camera_table, Mapping) else True
        if not isinstance(enabled, bool):
            raise ConfigError(f"sensors.camera.enabled = {enabled!r} must be true or false")
        camera = None
        if enabled:
            rest = {k: v for k, v in camera_table.items() if k != "enabled"} \
                if isinstance(camera_table, Mapping) else camera_table
            camera = _build(CameraConfig, "sensors.camera", rest)
        return SensorsConfig(lidars, scan, camera)
    except ConfigError as e:
        raise ConfigError(f"{source}: {e}") from None


def sensors_from_profile_file(path: str | Path | None = None,
                              footprint: Footprint = DEFAULT_FOOTPRINT) -> SensorsConfig:
    """The ``[sensors]`` of a robot profile TOML (None = the packaged default profile),
    checked against the footprint."""
    from lowerbase.firmware_model.profile import default_profile_path

    p = Path(path) if path is not None else default_profile_path()
    config = sensors_from_dict(read_toml(p, "profile").get("sensors", {}), source=str(p))
    config.check_mounts(footprint)
    return config
