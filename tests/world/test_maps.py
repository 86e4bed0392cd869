"""map_server YAML + PGM/PNG reading and writing: closed-form cells, an independent per-pixel
transcription of map_server's image_loader, byte-level PGM checks, round trips, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from lowerbase.errors import MapError
from lowerbase.world import mapgen
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.maps import (
    MAP_NAMES,
    MapMeta,
    load_map,
    maps_dir,
    parse_map_yaml,
    pixels_to_cells,
    read_map,
    resolve_map,
    write_map,
)

YAML = ("image: {image}\nresolution: 0.05\norigin: [-1.5, 2.0, 0.0]\nnegate: {negate}\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n{mode}")


def write_pgm(path: Path, rows: list[list[int]]) -> None:
    """A binary PGM (P5) written byte by byte, independent of Pillow."""
    height, width = len(rows), len(rows[0])
    path.write_bytes(f"P5\n# test\n{width} {height}\n255\n".encode()
                     + bytes(v for row in rows for v in row))


def map_files(tmp_path: Path, rows: list[list[int]], negate: int = 0, mode: str = "") -> Path:
    write_pgm(tmp_path / "m.pgm", rows)
    yaml_path = tmp_path / "m.yaml"
    yaml_path.write_text(YAML.format(image="m.pgm", negate=negate,
                                     mode=f"mode: {mode}\n" if mode else ""))
    return yaml_path


def test_trinary_thresholds_and_row_flip(tmp_path: Path) -> None:
    # p = (255 - v) / 255: 0 -> 1.0 (occupied), 254 -> 0.0039 (free), 205 -> 0.19608 (> 0.196:
    # unknown), 90 -> 0.647 (< 0.65: unknown), 89 -> 0.651 (occupied), 255 -> 0 (free)
    grid = read_map(map_files(tmp_path, [[0, 254, 205, 90], [89, 255, 204, 0]]))
    assert grid.resolution == 0.05 and grid.origin == (-1.5, 2.0, 0.0)
    assert (grid.width, grid.height) == (4, 2)
    # the image's top row is the grid's highest row
    assert grid.data.tolist() == [[100, 0, -1, 100], [100, 0, -1, -1]]


def test_negate_swaps_black_and_white(tmp_path: Path) -> None:
    grid = read_map(map_files(tmp_path, [[0, 255, 205, 50]], negate=1))
    # negate: c -> 255 - c; 205 -> 50 -> p = 0.804 (occupied); 50 -> 205 -> p = 0.196 (unknown)
    assert grid.data.tolist() == [[0, 100, 100, -1]]


def test_scale_mode_closed_form(tmp_path: Path) -> None:
    # 128: p = 127/255 = 0.49804, ratio = (0.49804 - 0.196) / 0.454 = 0.66529,
    # 1 + 98 * 0.66529 = 66.2 -> 66;  200: p = 0.21569 -> ratio 0.04336 -> 5.25 -> 5
    grid = read_map(map_files(tmp_path, [[128, 200, 0, 255]], mode="scale"))
    assert grid.data.tolist() == [[66, 5, 100, 0]]


def test_raw_mode_is_the_byte_as_a_signed_byte(tmp_path: Path) -> None:
    grid = read_map(map_files(tmp_path, [[0, 100, 200, 255]], mode="raw"))
    assert grid.data.tolist() == [[0, 100, -56, -1]]
    grid = read_map(map_files(tmp_path, [[0, 100, 200, 255]], negate=1, mode="raw"))
    assert grid.data.tolist() == [[-1, -101, 55, 0]]


def test_rgba_alpha_counts_in_trinary_and_marks_unknown_in_scale(tmp_path: Path) -> None:
    pixels = np.array([[[100, 100, 100, 0], [100, 100, 100, 255]]], np.uint8)
    Image.fromarray(pixels, "RGBA").save(tmp_path / "m.png")
    yaml_path = tmp_path / "m.yaml"
    for mode, expected in (("trinary", [[100, -1]]), ("scale", [[-1, 89]])):
        yaml_path.write_text(YAML.format(image="m.png", negate=0, mode=f"mode: {mode}\n"))
        # trinary: (3*100 + 0)/4 = 75 -> p 0.706 occupied; (300 + 255)/4 = 138.75 -> p 0.456.
        # scale: colour 100 -> p 0.6078, ratio 0.9071 -> 89.9 -> 89; alpha 0 -> unknown
        assert read_map(yaml_path).data.tolist() == expected, mode


def image_loader_reference(pixels: np.ndarray, has_alpha: bool, negate: bool, occ_th: float,
                           free_th: float, mode: str) -> np.ndarray:
    """map_server's loadMapFromFile transcribed statement by statement (scalar loops)."""
    height, width, n_channels = pixels.shape
    avg_channels = n_channels if (mode == "trinary" or not has_alpha) else n_channels - 1
    out = np.zeros((height, width), np.int8)
    for j in range(height):
        for i in range(width):
            color_sum = sum(int(pixels[j, i, k]) for k in range(avg_channels))
            color_avg = color_sum / float(avg_channels)
            alpha = 1 if n_channels == 1 else int(pixels[j, i, n_channels - 1])
            if negate:
                color_avg = 255 - color_avg
            if mode == "raw":
                value = int(color_avg) & 0xFF
            else:
                occ = (255 - color_avg) / 255.0
                if occ > occ_th:
                    value = 100
                elif occ < free_th:
                    value = 0
                elif mode == "trinary" or alpha < 1.0:
                    value = 255  # -1 as unsigned char
                else:
                    ratio = (occ - free_th) / (occ_th - free_th)
                    value = int(1 + 98 * ratio)
            out[height - j - 1, i] = value - 256 if value > 127 else value
    return out


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
@pytest.mark.parametrize("negate", [False, True])
def test_vectorised_loader_equals_the_per_pixel_transcription(channels: int, mode: str,
                                                             negate: bool) -> None:
    rng = np.random.default_rng(channels * 10 + len(mode) + negate)
    pixels = rng.integers(0, 256, size=(9, 13, channels), dtype=np.uint8)
    pixels[0, :4, -1] = 0  # some transparent/zero last channels
    has_alpha = channels == 4
    meta = MapMeta(image=Path("x"), resolution=0.05, origin=(0.0, 0.0, 0.0), negate=negate,
                   occupied_thresh=0.6, free_thresh=0.3, mode=mode)
    expected = image_loader_reference(pixels, has_alpha, negate, 0.6, 0.3, mode)
    assert np.array_equal(pixels_to_cells(pixels, has_alpha, meta), expected)


def test_written_pgm_bytes_are_map_savers(tmp_path: Path) -> None:
    data = np.array([[0, 100, -1], [25, 26, 64], [65, 3, -1]], np.int8)  # row 0 = bottom
    write_map(OccupancyGrid(data, 0.1, (1.0, -2.0, 0.0)), tmp_path / "w.yaml")
    raw = (tmp_path / "w.pgm").read_bytes()
    header = b"P5\n3 3\n255\n"
    assert raw.startswith(header)
    # top row first; free (0..25) 254, occupied (>= 65) 0, everything else 205
    assert raw[len(header):] == bytes([0, 254, 205, 254, 205, 205, 254, 0, 205])
    meta = parse_map_yaml(tmp_path / "w.yaml")
    assert (meta.image, meta.resolution, meta.origin, meta.mode) == (
        tmp_path / "w.pgm", 0.1, (1.0, -2.0, 0.0), "trinary")


@pytest.mark.parametrize("image", ["r.pgm", "r.png"])
def test_round_trips(tmp_path: Path, image: str) -> None:
    rng = np.random.default_rng(7)
    trinary = rng.choice(np.array([-1, 0, 100], np.int8), size=(31, 17))
    grid = OccupancyGrid(trinary, 0.05, (-3.25, 4.5, 0.0))
    back = read_map(write_map(grid, tmp_path / "t.yaml", image=image))
    assert np.array_equal(back.data, trinary)
    assert (back.resolution, back.origin) == (0.05, (-3.25, 4.5, 0.0))
    every = np.arange(-128, 128, dtype=np.int8).reshape(16, 16)
    back = read_map(write_map(OccupancyGrid(every, 0.025), tmp_path / "raw.yaml", image=image,
                              mode="raw"))
    assert np.array_equal(back.data, every)


@pytest.mark.parametrize(("text", "needle"), [
    ("resolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
     "missing image"),
    ("image: m.pgm\nresolution: 0\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "'resolution' must be positive"),
    ("image: m.pgm\nresolution: .nan\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "'resolution' must be a finite number"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "'origin' must be [x, y, yaw]"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 2\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "'negate' must be 0 or 1"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.2\n"
     "free_thresh: 0.65\n", "free_thresh < occupied_thresh"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 1.5\n"
     "free_thresh: 0.2\n", "occupied_thresh <= 1"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\nmode: binary\n", "unknown mode 'binary'"),
    ("image: ''\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "'image' must be a non-empty"),
    ("- just\n- a list\n", "must be a mapping"),
    ("image: [unclosed\n", "not valid YAML"),
    ("image: gone.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "gone.pgm does not exist"),
    ("image: bad.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "cannot be read as an image"),
    ("image: pal.png\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "is P (use 8-bit grayscale"),
])
def test_malformed_maps_are_refused_in_one_line(tmp_path: Path, text: str, needle: str) -> None:
    (tmp_path / "bad.pgm").write_bytes(b"P5\n4 4\n255\n\x00")  # truncated pixel data
    Image.new("P", (3, 3)).save(tmp_path / "pal.png")
    (tmp_path / "m.yaml").write_text(text)
    with pytest.raises(MapError) as err:
        read_map(tmp_path / "m.yaml")
    message = str(err.value)
    assert needle in message and "\n" not in message


def test_missing_yaml_and_unknown_name() -> None:
    with pytest.raises(MapError, match="does not exist"):
        load_map("/nonexistent/map.yaml")
    with pytest.raises(MapError) as err:
        load_map("wearhouse")
    assert str(err.value) == ("unknown map 'wearhouse': known maps are corridor_loop, "
                              "empty_room, warehouse (or give the path of a map .yaml)")



def test_names_resolve_to_the_shipped_files() -> None:
    for name in MAP_NAMES:
        path = resolve_map(name)
        assert path.name == f"{name}.yaml" and path.is_file()
        grid = load_map(name)
        assert grid.resolution == 0.05 and grid.origin == (0.0, 0.0, 0.0)
    assert resolve_map() == resolve_map("warehouse")


def test_shipped_files_are_what_the_generator_draws(tmp_path: Path) -> None:
    written = mapgen.write_library(tmp_path)
    assert sorted(p.name for p in written) == sorted(
        f"{n}.{ext}" for n in MAP_NAMES for ext in ("yaml", "pgm", "places.yaml"))
    for path in written:
        shipped = maps_dir() / path.name
        assert shipped.read_bytes() == path.read_bytes(), (
            f"{shipped} differs from the generator: run python -m lowerbase.world.mapgen")
    for name, (make, _) in mapgen.GENERATORS.items():
        assert np.array_equal(load_map(name).data, make().data)


def test_warehouse_scale_and_aisles() -> None:
    grid = load_map("warehouse")
    assert grid.size_m == pytest.approx((30.0, 20.0))
    occupied = grid.occupied()
    for block, (centres, (x0, x1)) in mapgen.WAREHOUSE_AISLES.items():
        c0, c1 = round(x0 / 0.05), round(x1 / 0.05)
        for y in centres:
            # the aisle is 1.5 m of free floor over the rack's whole length ...
            r0, r1 = round((y - 0.75) / 0.05), round((y + 0.75) / 0.05)
            assert (grid.data[r0:r1, c0:c1] == 0).all(), (block, y)
            # ... bounded by racks (occupied) on both sides, at least where the racks are
            assert occupied[r0 - 1, c0:c1].mean() > 0.5 and occupied[r1, c0:c1].mean() > 0.5
    # the charging station sits on the south wall
    cx0, cy0, cx1, cy1 = mapgen.WAREHOUSE_CHARGER
    assert occupied[round(cy0 / 0.05):round(cy1 / 0.05), round(cx0 / 0.05):round(cx1 / 0.05)].all()


@pytest.mark.parametrize("name", MAP_NAMES)
def test_maps_are_not_symmetric(name: str) -> None:
    """A localizer needs a map that differs from its mirror images and its 180-degree turn."""
    occupied = load_map(name).occupied()
    for other in (occupied[::-1], occupied[:, ::-1], occupied[::-1, ::-1]):
        assert (occupied != other).sum() > 200, name
