"""lowerbase.world.lazy_scan: a scan whose random numbers are drawn at its tick and whose ray
cast runs only when it is read is bit for bit the scan cast at once, and every later scan is
unchanged by the ones never cast; the localizer does not read a scan it skips."""

from __future__ import annotations

import numpy as np

from lowerbase.clock import SimClock
from lowerbase.world.lazy_scan import LazyScan, resolve
from lowerbase.world.lidar import LidarConfig, LidarRig, MergedScanConfig
from lowerbase.world.localization import Localizer
from lowerbase.world.raycast import Scene
from tests.world.localization_sim import feature_room
from tests.world.test_lidar import square_room

POSES = [(2.0, 2.0, 0.0), (2.1, 2.0, 0.1), (2.2, 2.05, 0.2), (2.3, 2.1, 0.3)]


def rig() -> LidarRig:
    noisy = dict(range_sigma=0.01, dropout_prob=0.05, range_min=0.05, range_max=20.0)
    front = LidarConfig(name="front", x=0.3, seed=11, **noisy)  # type: ignore[arg-type]
    back = LidarConfig(name="back", x=-0.3, yaw=np.pi, seed=12, **noisy)  # type: ignore[arg-type]
    return LidarRig([front, back], MergedScanConfig(beams=360))


def test_lazy_scans_are_the_eager_ones_and_skipping_some_changes_no_other() -> None:
    room = Scene(square_room())
    eager_rig, lazy_rig = rig(), rig()
    eager = [eager_rig.scan(room, p, 0.04 * i) for i, p in enumerate(POSES)]
    made: list[int] = []

    def lazy(i: int) -> LazyScan:
        draws, pose, t = lazy_rig.draw(), POSES[i], 0.04 * i

        def make() -> object:
            made.append(i)
            return lazy_rig.scan(room, pose, t, draws)
        return LazyScan("base_link", t, make)  # type: ignore[arg-type]

    scans = [lazy(i) for i in range(len(POSES))]
    assert made == [] and not any(s.cast for s in scans)
    for i in (3, 1):  # read out of order; 0 and 2 never cast
        got = resolve(scans[i])
        assert np.array_equal(got.ranges, eager[i].ranges, equal_nan=True)
        assert got.stamp == eager[i].stamp and got.frame_id == eager[i].frame_id
    assert resolve(scans[1]) is resolve(scans[1]) and made == [3, 1]  # cast once each
    assert scans[2].frame_id == "base_link" and not scans[2].cast
    assert np.array_equal(scans[3].ranges, eager[3].ranges, equal_nan=True)


def test_the_localizer_reads_no_scan_it_skips_for_small_motion() -> None:
    grid = feature_room()
    loc = Localizer(grid, clock=SimClock(), seed=1, initial_pose=(3.0, 3.0, 0.0))
    scene = Scene(grid)
    rig_ = rig()

    def lazy(pose: tuple[float, float, float]) -> LazyScan:
        draws = rig_.draw()
        return LazyScan("base_link", 0.0, lambda: rig_.scan(scene, pose, 0.0, draws))

    first = lazy((3.0, 3.0, 0.0))
    assert loc.update((0.0, 0.0, 0.0), first) is not None and first.cast
    small = lazy((3.05, 3.0, 0.0))  # 5 cm: below update_min_d
    assert loc.update((0.05, 0.0, 0.0), small) is None and not small.cast
    assert loc.stats.skipped_small_motion == 1
    far = lazy((3.3, 3.0, 0.0))
    assert loc.update((0.3, 0.0, 0.0), far) is not None and far.cast
