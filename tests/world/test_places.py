"""Named places: the shipped sidecars, their checks against the map, the file format."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from lowerbase.errors import MapError
from lowerbase.world import mapgen
from lowerbase.world.footprint import DEFAULT_FOOTPRINT, contact
from lowerbase.world.maps import MAP_NAMES, load_map, maps_dir
from lowerbase.world.places import (
    Charger,
    Places,
    format_places,
    load_places,
    places_path,
    read_places,
    write_places,
)

PADDED = DEFAULT_FOOTPRINT.padded(0.1)


def test_warehouse_places() -> None:
    places = load_places("warehouse")
    assert len(places.storage) == 5 * 3 + 4 * 2
    assert all(isinstance(k, str) for k in places.storage)
    assert places.pose("A1-01") == (9.5, 4.75, 0.0)
    assert places.pose("B4-02") == (26.5, 12.25, 0.0)
    assert places.charger == Charger((3.3, 1.0, -1.570796), (3.3, 2.0, -1.570796))
    assert places.pose("charger_approach") == (3.3, 2.0, -1.570796)
    with pytest.raises(MapError, match=r"unknown place 'Z9': this map has A1-01, A1-02"):
        places.pose("Z9")


@pytest.mark.parametrize("name", MAP_NAMES)
def test_padded_robot_turns_in_place_at_every_place_but_the_docked_one(name: str) -> None:
    grid = load_map(name)
    for place, (x, y, _) in load_places(name).named().items():
        if place == "charger":
            continue  # docked: closer to the charger than the padding, by design
        for yaw in np.linspace(-math.pi, math.pi, 37):
            assert contact((x, y, yaw), grid, footprint=PADDED) is None, (place, yaw)


def test_padded_robot_drives_every_warehouse_aisle() -> None:
    grid = load_map("warehouse")
    for centres, (x0, x1) in mapgen.WAREHOUSE_AISLES.values():
        for y in centres:
            for x in np.arange(x0, x1 + 1e-9, 0.1):
                assert contact((x, y, 0.0), grid, footprint=PADDED) is None, (x, y)
    # and the 1.5 m aisle is narrow: 0.4 m off the centre line the padded robot touches a rack
    assert contact((12.0, 4.75 + 0.4, 0.0), grid, footprint=PADDED) is not None


def test_round_trip(tmp_path: Path) -> None:
    places = Places(storage={"101": (1.5, -2.25, 0.5), "A-7": (0.0, 3.0, -math.pi)},
                    charger=Charger((1.0, 2.0, 3.0), (1.5, 2.0, 3.0)),
                    poses={"home": (0.1, 0.2, 0.3)})
    back = read_places(write_places(places, tmp_path / "m.places.yaml", "title"))
    assert back.storage == {"101": (1.5, -2.25, 0.5), "A-7": (0.0, 3.0, -3.141593)}
    assert back.charger == places.charger and back.poses == places.poses
    assert format_places(Places()) == "\n"


def test_map_without_sidecar_has_no_places(tmp_path: Path) -> None:
    shutil.copy(maps_dir() / "empty_room.yaml", tmp_path / "room.yaml")
    shutil.copy(maps_dir() / "empty_room.pgm", tmp_path / "empty_room.pgm")
    assert load_places(tmp_path / "room.yaml") == Places()
    assert places_path(tmp_path / "room.yaml") == tmp_path / "room.places.yaml"


@pytest.mark.parametrize(("text", "needle"), [
    ("storage:\n  101: [1, 2, 0]\n", "names are non-empty strings, got 101 (quote it: \"101\")"),
    ("storage:\n  'A': [1, 2]\n", "storage 'A' must be [x, y, yaw]"),
    ("storage:\n  'A': [1, .nan, 0]\n", "must be [x, y, yaw] (finite numbers)"),
    ("charger:\n  pose: [1, 4, 0]\n", "'charger' needs exactly pose and approach"),
    ("shelves: {}\n", "unknown section(s) shelves"),
    ("storage: {charger: [2, 4, 0]}\nposes: {charger: [2, 4, 0]}\n", "charger named twice"),
    ("- 1\n", "a places file is a mapping"),
    ("storage: [unclosed\n", "not valid YAML"),
    ("poses:\n  inside_the_wall: [0.1, 4.0, 0.0]\n",
     "place 'inside_the_wall' at (0.100, 4.000, yaw 0.000) would touch wall and map_edge"),
    ("storage:\n  'R9': [9.7, 2.0, 0.0]\n",
     "place 'R9' at (9.700, 2.000, yaw 0.000) would touch wall"),
])
def test_bad_places_are_refused_in_one_line(tmp_path: Path, text: str, needle: str) -> None:
    shutil.copy(maps_dir() / "empty_room.yaml", tmp_path / "room.yaml")
    shutil.copy(maps_dir() / "empty_room.pgm", tmp_path / "empty_room.pgm")
    (tmp_path / "room.places.yaml").write_text(text)
    with pytest.raises(MapError) as err:
        load_places(tmp_path / "room.yaml")
    assert needle in str(err.value) and "\n" not in str(err.value)
