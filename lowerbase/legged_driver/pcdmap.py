"""Point-cloud maps for set_map: sensor_msgs/PointCloud2 <-> numpy, PCD files via pypcd4.

ROS-free: :func:`cloud_points` reads any object with PointCloud2's fields (height, width, fields
with name/offset/datatype/count, is_bigendian, point_step, row_step, data, is_dense), so the
generated message and the tests' plain objects both work. Bad clouds raise
:class:`~lowerbase.errors.MapError` saying what is wrong: x, y, z fields missing, with a count
other than 1, overlapping or not fitting ``point_step``; ``data`` not exactly ``height x
row_step`` bytes; no finite point, or points beyond :data:`MAX_COORDINATE`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lowerbase.errors import MapError
from lowerbase.text import clip, point

#: sensor_msgs/PointField datatypes -> numpy
DATATYPES: dict[int, str] = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4",
                             8: "f8"}
FLOAT32 = 7
#: [m] a map point farther out than this is not a map's (1000 km; float32 resolves 6 cm there)
MAX_COORDINATE = 1e6
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")


@dataclass
class PointFieldSpec:
    name: str
    offset: int
    datatype: int
    count: int = 1


@dataclass
class Cloud:
    """The PointCloud2 fields lowerbase uses (a stand-in for the message outside ROS)."""

    height: int
    width: int
    fields: list[PointFieldSpec]
    is_bigendian: bool
    point_step: int
    row_step: int
    data: bytes
    is_dense: bool = True
    frame_id: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def cloud_points(msg: Any) -> np.ndarray:
    """The finite x, y, z of a PointCloud2 as an (N, 3) float64 array."""
    try:
        height, width = int(msg.height), int(msg.width)
        point_step, row_step = int(msg.point_step), int(msg.row_step)
        data = bytes(msg.data)
        specs = {f.name: f for f in msg.fields}
    except (AttributeError, TypeError, ValueError) as exc:
        raise MapError(f"not a PointCloud2: {exc}") from None
    missing = [n for n in "xyz" if n not in specs]
    if missing:
        raise MapError(f"the point cloud has no {', '.join(missing)} field "
                       f"(fields: {clip(str(sorted(specs)))})")
    if height < 0 or width < 0 or height * width == 0:
        raise MapError("the point cloud is empty")
    if point_step <= 0:
        raise MapError(f"the point cloud's point_step {point_step} must be > 0 bytes")
    if row_step < width * point_step:
        raise MapError(f"the point cloud's data does not hold {height} x {width} points of "
                       f"{point_step} bytes: row_step {row_step} < width x point_step")
    if len(data) != height * row_step:
        raise MapError(f"the point cloud's data is {len(data)} bytes, not height x row_step = "
                       f"{height * row_step}: it does not hold {height} x {width} points of "
                       f"{point_step} bytes")
    order = ">" if msg.is_bigendian else "<"
    names: list[str] = []
    formats: list[str] = []
    offsets: list[int] = []
    spans: list[tuple[int, int]] = []
    for n in "xyz":
        spec = specs[n]
        kind = DATATYPES.get(int(spec.datatype))
        offset = int(spec.offset)
        if kind is None or offset < 0 or offset + np.dtype(kind).itemsize > point_step:
            raise MapError(f"field {n}: datatype {spec.datatype} at offset {spec.offset} does "
                           f"not fit a {point_step}-byte point")
        if int(spec.count) != 1:
            raise MapError(f"the point cloud's field {n} has count {spec.count}: x, y, z need "
                           f"count 1")
        for other, (a, b) in zip(names, spans, strict=True):
            if offset < b and a < offset + np.dtype(kind).itemsize:
                raise MapError(f"the point cloud's fields {other} and {n} overlap (offsets "
                               f"{a} and {offset})")
        names.append(n)
        formats.append(order + kind)
        offsets.append(offset)
        spans.append((offset, offset + np.dtype(kind).itemsize))
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets,
                      "itemsize": point_step})
    rows = np.frombuffer(data, dtype=np.uint8, count=height * row_step).reshape(height,
                                                                                row_step)
    packed = np.ascontiguousarray(rows[:, :width * point_step]).view(dtype).reshape(-1)
    with np.errstate(invalid="ignore"):  # signalling NaNs in the bytes: dropped below
        xyz = np.stack([packed[n].astype(np.float64) for n in "xyz"], axis=1)
    finite = np.isfinite(xyz).all(axis=1)
    xyz = xyz[finite]
    if len(xyz) == 0:
        raise MapError("the point cloud has no finite point")
    far = np.abs(xyz).max(axis=1) > MAX_COORDINATE
    if far.any():
        i = int(np.argmax(far))
        raise MapError(f"{int(far.sum())} of the point cloud's {len(xyz)} finite points lie "
                       f"beyond {MAX_COORDINATE:g} m, e.g. {point(*xyz[i])}: not a map (random "
                       f"bytes or a wrong datatype/endianness?)")
    return xyz


def make_cloud(points: np.ndarray, frame_id: str = "map") -> Cloud:
    """An x, y, z float32 PointCloud2 (one row, little-endian) of (N, 3) ``points``."""
    xyz = np.asarray(points, dtype="<f4").reshape(-1, 3)
    fields = [PointFieldSpec(n, 4 * i, FLOAT32) for i, n in enumerate("xyz")]
    return Cloud(height=1, width=len(xyz), fields=fields, is_bigendian=False, point_step=12,
                 row_step=12 * len(xyz), data=xyz.tobytes(),
                 is_dense=bool(np.isfinite(xyz).all()), frame_id=frame_id)


def check_name(name: str) -> str:
    """A map name usable as a frame and a file name, or MapError."""
    if not _NAME.match(name) or name in ("odom", "gps"):
        raise MapError(f"map name {name!r}: use 1-64 letters, digits, '_', '.', '-' (not "
                       "'odom' or 'gps')")
    return name


def write_pcd(path: str | Path, points: np.ndarray) -> Path:
    """Save (N, 3) points as a binary PCD (x, y, z float32) with pypcd4."""
    from pypcd4 import Encoding, PointCloud

    xyz = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    target = Path(path)
    tmp = target.with_name(f".{target.name}.tmp")
    try:
        PointCloud.from_xyz_points(xyz).save(tmp, encoding=Encoding.BINARY)
        tmp.replace(target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise MapError(f"cannot write {target}: {exc.strerror or exc}") from None
    return target


def read_pcd(path: str | Path) -> np.ndarray:
    """The x, y, z of a PCD file (any encoding pypcd4 reads) as (N, 3) float64."""
    from pypcd4 import PointCloud

    try:
        cloud = PointCloud.from_path(Path(path))
    except OSError as exc:
        raise MapError(f"cannot read {path}: {exc.strerror or exc}") from None
    except Exception as exc:  # pypcd4 raises plain errors for a malformed header
        raise MapError(f"{path} is not a readable PCD file: {exc}") from None
    if not {"x", "y", "z"} <= set(cloud.fields):
        raise MapError(f"{path} has no x, y, z fields (fields: {list(cloud.fields)})")
    return np.asarray(cloud.numpy(("x", "y", "z")), dtype=np.float64)
