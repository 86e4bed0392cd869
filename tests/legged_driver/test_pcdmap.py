"""PointCloud2 decoding, PCD round trips through pypcd4, and bad input as MapError."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from lowerbase.errors import MapError
from lowerbase.legged_driver.pcdmap import (
    Cloud,
    PointFieldSpec,
    check_name,
    cloud_points,
    make_cloud,
    read_pcd,
    write_pcd,
)

RNG = np.random.default_rng(7)


def test_round_trip_cloud_pcd_cloud(tmp_path: Path) -> None:
    pts = RNG.uniform(-50, 50, size=(1000, 3)).astype(np.float32).astype(np.float64)
    assert np.array_equal(cloud_points(make_cloud(pts)), pts)
    path = write_pcd(tmp_path / "office.pcd", pts)
    assert path.read_bytes().startswith(b"VERSION 0.7\n")
    header = path.read_bytes().split(b"DATA binary\n")[0].decode()
    assert "FIELDS x y z" in header and "POINTS 1000" in header
    assert np.array_equal(read_pcd(path), pts)
    assert not list(tmp_path.glob(".*.tmp"))


def test_ascii_pcd_written_by_hand_is_read(tmp_path: Path) -> None:
    text = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\n"
            "COUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n"
            "1.5 2 3 9\n-4 5.25 6 9\n")
    (tmp_path / "hand.pcd").write_text(text)
    assert read_pcd(tmp_path / "hand.pcd").tolist() == [[1.5, 2, 3], [-4, 5.25, 6]]


def test_padded_big_endian_organised_cloud_with_nans() -> None:
    """Fields out of order, float64 z, padding in points and rows, big-endian, a NaN point."""
    step, row = 24, 24 * 2 + 5
    rows = []
    values = [[(1.0, 2.0, 3.0), (float("nan"), 0.0, 0.0)], [(4.0, 5.0, 6.0), (7.0, 8.0, 9.0)]]
    for r in values:
        b = b""
        for x, y, z in r:
            b += struct.pack(">d", z) + struct.pack(">f", y) + b"\0" * 4 + struct.pack(">f", x)
            b += b"\0" * 4
        rows.append(b + b"\xaa" * 5)
    cloud = Cloud(height=2, width=2, is_bigendian=True, point_step=step, row_step=row,
                  data=b"".join(rows), is_dense=False,
                  fields=[PointFieldSpec("z", 0, 8), PointFieldSpec("y", 8, 7),
                          PointFieldSpec("x", 16, 7)])
    assert cloud_points(cloud).tolist() == [[1, 2, 3], [4, 5, 6], [7, 8, 9]]


@pytest.mark.parametrize(("change", "match"), [
    ({"fields": [PointFieldSpec("x", 0, 7), PointFieldSpec("y", 4, 7)]}, "no z field"),
    ({"width": 0, "row_step": 0, "data": b""}, "empty"),
    ({"data": b"\0" * 11}, "does not hold"),
    ({"fields": [PointFieldSpec("x", 0, 7), PointFieldSpec("y", 4, 7),
                 PointFieldSpec("z", 10, 7)]}, "does not fit"),
    ({"fields": [PointFieldSpec("x", 0, 99), PointFieldSpec("y", 4, 7),
                 PointFieldSpec("z", 8, 7)]}, "datatype 99"),
    ({"data": np.full(3, np.nan, "<f4").tobytes()}, "no finite point"),
    # issue 22 item 21
    ({"fields": [PointFieldSpec("x", 0, 7, 0), PointFieldSpec("y", 4, 7),
                 PointFieldSpec("z", 8, 7)]}, "field x has count 0: x, y, z need count 1"),
    ({"fields": [PointFieldSpec("x", 0, 7), PointFieldSpec("y", 2, 7),
                 PointFieldSpec("z", 8, 7)]}, "fields x and y overlap"),
    ({"data": b"\0" * 12 + bytes(12000)}, r"data is 12012 bytes, not height x row_step = 12"),
    ({"point_step": 0}, "point_step 0"),
    ({"width": 1000, "row_step": 12000,
      "data": np.random.default_rng(7).bytes(12000)}, "beyond 1e\\+06 m"),
])
def test_bad_clouds_are_one_clear_error(change: dict[str, object], match: str) -> None:
    cloud = make_cloud(np.array([[1.0, 2.0, 3.0]]))
    for k, v in change.items():
        setattr(cloud, k, v)
    with pytest.raises(MapError, match=match):
        cloud_points(cloud)
    with pytest.raises(MapError, match="not a PointCloud2"):
        cloud_points(object())


def test_bad_files_and_names(tmp_path: Path) -> None:
    (tmp_path / "junk.pcd").write_text("hello\n")
    with pytest.raises(MapError, match="not a readable PCD"):
        read_pcd(tmp_path / "junk.pcd")
    with pytest.raises(MapError, match="cannot read"):
        read_pcd(tmp_path / "missing.pcd")
    with pytest.raises(MapError, match="cannot write"):
        write_pcd(tmp_path / "no" / "dir.pcd", np.zeros((1, 3)))
    assert check_name("office_2.f-1") == "office_2.f-1"
    for bad in ("", "../x", "a b", "odom", "gps", ".hidden", "x" * 65):
        with pytest.raises(MapError):
            check_name(bad)
