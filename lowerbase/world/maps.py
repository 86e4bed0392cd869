"""Maps in the ROS map_server format (YAML + PGM/PNG) and the map library shipped in the package.

Reading follows map_server's ``image_loader`` (ROS 1 noetic) pixel for pixel:

- the pixel's colour average ``c`` is the mean of its channels (in ``trinary`` mode alpha is
  averaged in too; in ``scale``/``raw`` modes it is not); ``negate`` replaces ``c`` by
  ``255 - c``;
- ``raw``: the cell value is ``c`` truncated to a byte, stored as a signed byte (so 255 -> -1);
- otherwise ``p = (255 - c) / 255``: occupied (100) if ``p > occupied_thresh``, free (0) if
  ``p < free_thresh``; in between unknown (-1) in ``trinary`` mode (or for a fully transparent
  pixel), else ``1 + 98 * (p - free) / (occupied - free)`` truncated (``scale``);
- image row 0 is the top: it becomes the grid's last row (row 0 of the grid is the lowest y).

Writing follows ``map_saver``: trinary PGM with 0 (occupied, value >= 65), 254 (free, value
0..25) and 205 (everything else, unknown included), or the cell bytes themselves (``raw``).
Unlike map_server, a malformed map is refused up front with one :class:`MapError` line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from PIL import Image, UnidentifiedImageError

from lowerbase.errors import MapError
from lowerbase.world.grid import OccupancyGrid

MODES = ("trinary", "scale", "raw")
#: the shipped library (lowerbase/world/maps/NAME.yaml), drawn by lowerbase.world.mapgen
MAP_NAMES = ("corridor_loop", "empty_room", "warehouse")
DEFAULT_MAP = "warehouse"
#: map_saver's defaults (ROS 1): what it writes and the thresholds it writes into the YAML
SAVER_OCCUPIED = 65
SAVER_FREE = 25
SAVER_OCCUPIED_THRESH = 0.65
SAVER_FREE_THRESH = 0.196
IMAGE_SUFFIXES = (".pgm", ".png")


@dataclass(frozen=True)
class MapMeta:
    """A map YAML's contents (the image path resolved against the YAML's folder)."""

    image: Path
    resolution: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str = "trinary"


def maps_dir() -> Path:
    """Folder of the shipped map library."""
    return Path(str(resources.files("lowerbase") / "world" / "maps"))


def _number(doc: dict[str, Any], key: str, where: Path) -> float:
    value = doc.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MapError(f"{where}: '{key}' must be a finite number, got {value!r}")
    return float(value)


def parse_map_yaml(path: Path | str) -> MapMeta:
    """Read and check a map_server YAML; :class:`MapError` (one line) if it is unusable."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MapError(f"map file {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MapError(f"cannot read map file {path}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" (line {mark.line + 1})" if mark is not None else ""
        raise MapError(f"{path}: not valid YAML{at}") from None
    if not isinstance(doc, dict):
        raise MapError(f"{path}: a map YAML must be a mapping with image, resolution, origin, "
                       "negate, occupied_thresh and free_thresh")
    missing = [k for k in ("image", "resolution", "origin", "negate", "occupied_thresh",
                           "free_thresh") if k not in doc]
    if missing:
        raise MapError(f"{path}: missing {', '.join(missing)}")
    image = doc["image"]
    if not isinstance(image, str) or not image.strip():
        raise MapError(f"{path}: 'image' must be a non-empty file name, got {image!r}")
    resolution = _number(doc, "resolution", path)
    if resolution <= 0:
        raise MapError(f"{path}: 'resolution' must be positive metres per cell, got {resolution}")
    origin = doc["origin"]
    if (not isinstance(origin, list) or len(origin) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) for v in origin)):
        raise MapError(f"{path}: 'origin' must be [x, y, yaw] (finite numbers), got {origin!r}")
    negate = doc["negate"]
    if negate not in (0, 1) or isinstance(negate, float):  # True/False are 1/0 too
        raise MapError(f"{path}: 'negate' must be 0 or 1, got {negate!r}")
    occupied = _number(doc, "occupied_thresh", path)
    free = _number(doc, "free_thresh", path)
    if not 0.0 <= free < occupied <= 1.0:
        raise MapError(f"{path}: thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1, "
                       f"got free_thresh {free}, occupied_thresh {occupied}")
    mode = doc.get("mode", "trinary")
    if mode not in MODES:
        raise MapError(f"{path}: unknown mode {mode!r} (use one of {', '.join(MODES)})")
    image_path = Path(image)
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    return MapMeta(image=image_path, resolution=resolution,
                   origin=(float(origin[0]), float(origin[1]), float(origin[2])),
                   negate=bool(negate), occupied_thresh=occupied, free_thresh=free, mode=mode)


def read_image(path: Path) -> tuple[np.ndarray, bool]:
    """Pixels as uint8 (height, width, channels) in file order (row 0 = top), and has_alpha.

    Grayscale, grayscale + alpha (as RGBA, as SDL_image loads it), RGB and RGBA are accepted;
    1-bit images become 0/255 gray; palette and 16-bit images are refused.
    """
    try:
        with Image.open(path) as img:
            img.load()
            mode = img.mode
            if mode == "1":
                img = img.convert("L")
                mode = "L"
            if mode == "LA":
                gray, alpha = (np.asarray(b) for b in img.split())
                pixels = np.stack([gray, gray, gray, alpha], axis=-1)
                return pixels.astype(np.uint8), True
            if mode not in ("L", "RGB", "RGBA"):
                raise MapError(f"map image {path} is {mode} (use 8-bit grayscale, RGB or RGBA)")
            pixels = np.asarray(img, dtype=np.uint8)
    except FileNotFoundError:
        raise MapError(f"map image {path} does not exist") from None
    except (UnidentifiedImageError, Image.DecompressionBombError, OSError, SyntaxError,
            ValueError) as exc:
        raise MapError(f"map image {path} cannot be read as an image: {exc}") from None
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    return pixels, mode == "RGBA"


def pixels_to_cells(pixels: np.ndarray, has_alpha: bool, meta: MapMeta) -> np.ndarray:
    """map_server's image_loader on a (height, width, channels) uint8 array -> int8 grid data."""
    channels = pixels.shape[2]
    averaged = channels if (meta.mode == "trinary" or not has_alpha) else channels - 1
    color = pixels[:, :, :averaged].astype(np.int64).sum(axis=2) / float(averaged)
    if meta.negate:
        color = 255.0 - color
    if meta.mode == "raw":
        cells = color.astype(np.uint8).view(np.int8)  # (unsigned char) then int8, as C does
    else:
        occ = (255.0 - color) / 255.0
        ratio = (occ - meta.free_thresh) / (meta.occupied_thresh - meta.free_thresh)
        scaled = (1.0 + 98.0 * ratio).astype(np.int64)
        # map_server takes the last channel as alpha whenever there is more than one (so an RGB
        # pixel with blue 0 counts as transparent in scale mode): kept, to read maps as it does
        transparent = pixels[:, :, -1] == 0 if channels > 1 else np.zeros(occ.shape, bool)
        middle = np.full(occ.shape, -1, np.int64) if meta.mode == "trinary" else \
            np.where(transparent, -1, scaled)
        cells = np.where(occ > meta.occupied_thresh, 100,
                         np.where(occ < meta.free_thresh, 0, middle)).astype(np.int8)
    return np.ascontiguousarray(cells[::-1])


def read_map(yaml_path: Path | str) -> OccupancyGrid:
    """A map_server map (YAML + image) as an :class:`OccupancyGrid`."""
    meta = parse_map_yaml(yaml_path)
    pixels, has_alpha = read_image(meta.image)
    return OccupancyGrid(pixels_to_cells(pixels, has_alpha, meta), meta.resolution, meta.origin)


def cells_to_pixels(data: np.ndarray, mode: str = "trinary") -> np.ndarray:
    """Grid data -> uint8 image (row 0 = top), as map_saver writes it (trinary) or raw bytes."""
    if mode == "raw":
        pixels = data.astype(np.int8).view(np.uint8)
    elif mode == "trinary":
        pixels = np.full(data.shape, 205, np.uint8)
        pixels[(data >= 0) & (data <= SAVER_FREE)] = 254
        pixels[data >= SAVER_OCCUPIED] = 0
    else:
        raise MapError(f"cannot write a map in mode {mode!r} (use trinary or raw)")
    return np.ascontiguousarray(pixels[::-1])


def format_map_yaml(image: str, grid: OccupancyGrid, mode: str) -> str:
    """The YAML text map_saver writes (plus the mode), with the image file name."""
    x, y, yaw = grid.origin
    return (f"image: {image}\n"
            f"mode: {mode}\n"
            f"resolution: {grid.resolution:.6f}\n"
            f"origin: [{x:.6f}, {y:.6f}, {yaw:.6f}]\n"
            f"negate: 0\n"
            f"occupied_thresh: {SAVER_OCCUPIED_THRESH}\n"
            f"free_thresh: {SAVER_FREE_THRESH}\n")


def write_map(grid: OccupancyGrid, yaml_path: Path | str, image: str | None = None,
              mode: str = "trinary") -> Path:
    """Write ``grid`` as YAML + image (PGM unless ``image`` ends in .png); returns the YAML path.

    ``trinary`` keeps -1/0/100 exactly (other values become 0, 100 or unknown as map_saver
    does); ``raw`` keeps every value.
    """
    yaml_path = Path(yaml_path)
    image = image or yaml_path.with_suffix(".pgm").name
    if Path(image).suffix.lower() not in IMAGE_SUFFIXES:
        raise MapError(f"map image name {image!r} must end in .pgm or .png")
    pixels = cells_to_pixels(grid.data, mode)
    try:
        Image.fromarray(pixels, mode="L").save(yaml_path.parent / image)
        yaml_path.write_text(format_map_yaml(image, grid, mode), encoding="utf-8")
    except OSError as exc:
        raise MapError(f"cannot write map {yaml_path}: {exc}") from None
    return yaml_path


def resolve_map(name_or_path: str | Path = DEFAULT_MAP) -> Path:
    """The YAML path of a shipped map name or of a map file path."""
    text = str(name_or_path)
    looks_like_path = (isinstance(name_or_path, Path) or "/" in text or "\\" in text
                       or text.endswith((".yaml", ".yml")))
    if not looks_like_path:
        if text in MAP_NAMES:
            return maps_dir() / f"{text}.yaml"
        raise MapError(f"unknown map {text!r}: known maps are {', '.join(MAP_NAMES)} "
                       "(or give the path of a map .yaml)")
    return Path(text)


def load_map(name_or_path: str | Path = DEFAULT_MAP) -> OccupancyGrid:
    """A shipped map by name (``warehouse``, ...) or any map_server YAML by path."""
    return read_map(resolve_map(name_or_path))
