"""WorldSim: emulator + driver + world on one simulated clock, checked against the emulator's
ground truth (localization error, map -> odom, contact) and for all-or-nothing bad input."""

from __future__ import annotations

import math

import pytest

from lowerbase.driver.core import LinkState
from lowerbase.errors import LowerbaseError, MapError, WorldError
from lowerbase.simloop.loop import SimLoop
from lowerbase.world.localization.poses import compose, inverse, wrap_scalar
from lowerbase.world.obstacles import Box, Obstacles
from lowerbase.world.sim import WorldConfig, WorldSim

LANE = (4.0, 2.0, 0.0)  # the warehouse's open lane along y = 2 (free to x = 28.6)


def ready(w: WorldSim) -> bool:
    return w.loop.driver.state == LinkState.READY and w.loop.mcu.state.name == "ACTIVE"


def started(cfg: WorldConfig) -> WorldSim:
    w = WorldSim(cfg)
    assert w.run_until(ready, timeout=3.0)
    return w


def test_particle_filter_tracks_a_drive_down_the_lane() -> None:
    w = started(WorldConfig(start=LANE, initial_error=(0.1, -0.1, 0.03), seed=4))
    errors: list[tuple[float, float]] = []

    def sample(s: WorldSim) -> None:
        if round(s.now / s.loop.mcu.dt) % 40 == 0:  # 5 Hz
            e = s.localization_error()
            if e is not None:
                errors.append(e)

    w.drive(0.5, 0.0, 16.0, on_step=sample)
    truth = w.true_pose()
    assert truth[0] == pytest.approx(4.0 + 0.5 * 15.4, abs=0.4)  # it really drove
    assert w.contact is None and not w.contact_events
    est = w.estimate
    assert est is not None and est.source == "filter"
    assert len(errors) > 60
    # the 14 cm initial error is gone at once; along a long lane the along-track position is
    # the weakly seen one (a few cm)
    assert max(p for p, _ in errors[5:]) < 0.12
    assert sorted(p for p, _ in errors)[int(0.95 * len(errors))] < 0.09
    late = errors[len(errors) // 2:]
    assert max(h for _, h in late) < math.radians(2.0)
    # map -> odom is where the driver's odom frame truly lies on the map (it absorbs the
    # odometry's drift): truth composed with the inverse of /odom, at the last update
    m2o = w.map_to_odom
    odom = w.odom_pose()
    assert m2o is not None and odom is not None
    true_m2o = compose(w.true_pose(), inverse(odom))
    assert math.hypot(m2o[0] - true_m2o[0], m2o[1] - true_m2o[1]) < 0.12
    assert abs(wrap_scalar(m2o[2] - true_m2o[2])) < math.radians(2.0)
    # /amcl_pose carries an honest covariance: the error within a few sigma
    err = math.hypot(est.pose[0] - w.true_pose()[0], est.pose[1] - w.true_pose()[1])
    assert err < 0.05 + 4 * est.sigma_xy


def test_ground_truth_mode_publishes_the_truth() -> None:
    w = started(WorldConfig(start=LANE, localization="truth"))
    w.drive(0.4, 0.2, 4.0)
    est = w.estimate
    assert est is not None and est.source == "truth"
    # the estimate is the truth at its stamp; amcl_pose moves it on with /odom since
    e = w.localization_error()
    assert e is not None and e[0] < 0.02 and e[1] < 0.01
    # at rest, a fresh update lands exactly on the truth
    w.run(2.0)
    assert abs(w.loop.mcu.truth.v) < 1e-9
    w.initial_pose(w.true_pose())
    w.run(0.1)
    assert w.estimate is not None
    tx, ty, tyaw = w.true_pose()
    ex, ey, eyaw = w.estimate.pose
    assert math.hypot(ex - tx, ey - ty) < 1e-6 and abs(wrap_scalar(eyaw - tyaw)) < 1e-6


def test_scan_is_the_last_ticks_scan_in_base_link() -> None:
    w = started(WorldConfig(start=LANE, localization="off"))
    w.run(0.5)
    scan = w.scan
    assert scan is not None and scan.frame_id == "base_link"
    period = 1.0 / w.rig.rate_hz
    assert w.now - period - 1e-9 <= scan.stamp <= w.now + 1e-9
    assert w.scan is scan  # cast once per tick
    # the lane's wall at y = 2 - clearance: the beam to the right (-pi/2) ends on it
    n = scan.ranges.size
    right = scan.ranges[round((-math.pi / 2 - scan.angle_min) / scan.angle_increment) % n]
    col, row = w.grid.world_to_cell(4.0, 2.0)
    occupied = w.grid.occupied()[: int(row), int(col)]
    wall_top = (int(occupied.nonzero()[0].max()) + 1) * w.grid.resolution + w.grid.origin[1]
    assert right == pytest.approx(2.0 - wall_top, abs=0.06)


def test_a_box_in_the_lane_stops_the_robot_and_is_reported() -> None:
    box = Box("pallet", center=(7.0, 2.0), size=(0.8, 1.2), height=0.15)
    w = started(WorldConfig(start=LANE, obstacles=Obstacles([box]), localization="off"))
    w.drive(0.5, 0.0, 10.0)
    x, _, yaw = w.true_pose()
    assert x + 0.4 * math.cos(yaw) <= 6.6 + 0.02
    assert x > 6.6 - 0.45
    assert w.contact is not None and w.contact.touched == ("pallet",)
    assert w.contact_events[0].touched == ("pallet",)
    assert w.truth.sample().contact


@pytest.mark.parametrize(("cfg", "error", "text"), [
    (WorldConfig(map="nowhere"), MapError, "unknown map 'nowhere'"),
    (WorldConfig(start=(8.5, 4.0, 0.0)), WorldError, "would touch wall"),
    (WorldConfig(start=(math.nan, 2.0, 0.0)), WorldError, "finite"),
    (WorldConfig(start="no-such-place"), MapError, "unknown place"),
    (WorldConfig(start=LANE, localization="guess"), WorldError, "not known"),
    (WorldConfig(start=LANE, obstacles=Obstacles([Box("b", (4.2, 2.0), (0.4, 0.4))])),
     WorldError, "would touch b"),
])
def test_bad_input_is_one_line_and_leaves_the_loop_alone(
        cfg: WorldConfig, error: type[LowerbaseError], text: str) -> None:
    loop = SimLoop(bms=None)
    with pytest.raises(error, match=text) as info:
        WorldSim(cfg, loop=loop)
    assert "\n" not in str(info.value)
    assert loop.surroundings is None  # nothing installed


def test_a_place_name_is_a_start_pose() -> None:
    w = WorldSim(WorldConfig(start="A1-01", localization="off"))
    assert w.true_pose() == pytest.approx((9.5, 4.75, 0.0))


def test_the_localizer_gets_odom_at_the_scans_stamp() -> None:
    """amcl looks the odom transform up at the scan's stamp (tf2 interpolation): the pose fed
    with each scan lies between the /odom samples around the scan's stamp, not the last
    sample before it (which is 20 ms old at every scan tick of this loop)."""
    w = started(WorldConfig(start=LANE, seed=2))
    samples: list[tuple[float, tuple[float, float, float]]] = []
    fed: list[tuple[float, tuple[float, float, float]]] = []
    update = w.localizer.update

    def spy(odom, scan, **kw):  # type: ignore[no-untyped-def]
        fed.append((scan.stamp, odom))
        return update(odom, scan, **kw)

    w.localizer.update = spy  # type: ignore[method-assign]

    def record(s: WorldSim) -> None:
        odo = s.loop.driver.odometry
        pose = s.odom_pose()
        if odo is not None and pose is not None and (not samples or odo.stamp > samples[-1][0]):
            samples.append((odo.stamp, pose))

    w.drive(0.5, 0.4, 6.0, on_step=record)
    assert len(fed) >= 5
    stamps = [t for t, _ in samples]
    for t, odom in fed[1:]:
        i = next(k for k, s in enumerate(stamps) if s >= t)
        (t0, p0), (t1, p1) = samples[i - 1], samples[i]
        assert t0 < t <= t1
        f = (t - t0) / (t1 - t0)
        assert 0.0 < f <= 1.0
        assert odom[0] == pytest.approx(p0[0] + f * (p1[0] - p0[0]), abs=1e-12)
        assert odom[1] == pytest.approx(p0[1] + f * (p1[1] - p0[1]), abs=1e-12)
        assert wrap_scalar(odom[2] - (p0[2] + f * wrap_scalar(p1[2] - p0[2]))) == \
            pytest.approx(0.0, abs=1e-12)


def test_ground_truth_mode_pairs_the_scans_odom_with_the_truth_at_the_scans_stamp() -> None:
    """The truth mode's estimate is the truth at the scan's stamp, as the /odom it is paired
    with (map -> odom = truth(t) odom(t)^-1). The truth when the scan is handled (up to a
    wheel cycle after the stamp) turned map -> odom by w * dt on every update of a turn."""
    w = started(WorldConfig(start=LANE, localization="truth"))
    truth: dict[float, tuple[float, float, float]] = {}
    fed: list[tuple[float, tuple[float, float, float]]] = []
    update = w.localizer.update

    def spy(odom, scan, **kw):  # type: ignore[no-untyped-def]
        est = update(odom, scan, **kw)
        if est is not None:
            fed.append((scan.stamp, est.pose))
        return est

    w.localizer.update = spy  # type: ignore[method-assign]
    w.drive(0.3, 0.6, 6.0, on_step=lambda s: truth.setdefault(round(s.now, 6), s.true_pose()))
    assert len(fed) >= 5
    for stamp, pose in fed:
        t = truth[round(stamp, 6)]
        assert math.hypot(pose[0] - t[0], pose[1] - t[1]) < 1e-9
        assert abs(wrap_scalar(pose[2] - t[2])) < 1e-9
