"""The waypoint mission: laps, indices, use_z, frames, gps against closed-form geodesy,
and the seed's response strings."""

from __future__ import annotations

import math

import pytest

from lowerbase.legged_driver.waypoints import (
    EMPTY,
    MAX_RANGE,
    MAX_WAYPOINTS,
    SET_SUCCESS,
    STOPPED,
    FollowerConfig,
    GpsDatum,
    Pose,
    Waypoint,
    WaypointFollower,
)

A = 6378137.0  # WGS84
F = 1 / 298.257223563
E2 = F * (2 - F)


def odom_only(wp: Waypoint) -> tuple[float, float, float]:
    if wp.frame != "odom":
        raise ValueError(f"unknown frame {wp.frame!r}")
    return wp.x, wp.y, wp.z


def walk(f: WaypointFollower, pose: Pose, seconds: float, dt: float = 0.02,
         z_of: object = None) -> tuple[Pose, list[tuple[int, int]]]:
    """Integrate the body command like an ideal holonomic base; record (index, laps_left)
    whenever the index changes."""
    trace = [(f.current_index, f.laps_left)]
    for _ in range(int(seconds / dt)):
        vx, vy, wz = f.step(pose)
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        x = pose.x + (c * vx - s * vy) * dt
        y = pose.y + (s * vx + c * vy) * dt
        z = z_of(x, y) if callable(z_of) else pose.z
        pose = Pose(x, y, z, pose.yaw + wz * dt)
        if (f.current_index, f.laps_left) != trace[-1]:
            trace.append((f.current_index, f.laps_left))
        if not f.active:
            break
    return pose, trace


SQUARE = [Waypoint("odom", 1, 0), Waypoint("odom", 1, 1), Waypoint("odom", 0, 1),
          Waypoint("odom", 0, 0)]


def test_seed_messages_and_refusals() -> None:
    f = WaypointFollower(odom_only)
    assert f.set([], 1, 0) == (False, EMPTY)
    assert f.get() == (True, EMPTY, [], 0, 0)
    assert f.set(SQUARE, 2, 0) == (True, SET_SUCCESS)
    ok, msg = f.set(SQUARE[:2], 1, 2)
    assert not ok and msg == "current_index 2 is out of range for 2 waypoints"
    ok, msg = f.set([Waypoint("odom", 0, 0), Waypoint("nowhere", 1, 1)], 1, 0)
    assert not ok and msg == "waypoint 1: unknown frame 'nowhere'"
    ok, msg = f.set([Waypoint("odom", math.nan, 0)], 1, 0)
    assert not ok and "finite" in msg
    assert not f.set([Waypoint("odom", 0, 0)] * (MAX_WAYPOINTS + 1), 1, 0)[0]
    # refused requests changed nothing
    assert f.get()[2] == SQUARE and f.get()[3:] == (2, 0)


def test_two_laps_visit_every_index_and_count_down() -> None:
    f = WaypointFollower(odom_only)
    f.set(SQUARE, 2, 1)  # first lap starts at index 1
    pose, trace = walk(f, Pose(0, 0, 0, 0), 60)
    assert trace == [(1, 2), (2, 2), (3, 2), (0, 1), (1, 1), (2, 1), (3, 1), (3, 0)]
    assert not f.active and f.laps_done == 2 and f.reached == 7
    assert math.hypot(pose.x, pose.y) <= f.config.xy_tolerance  # ends at the last waypoint
    ok, msg, wps, laps, index = f.get()
    assert (ok, msg, wps, laps, index) == (True, "mission complete", SQUARE, 0, 3)


def test_repetition_zero_is_endless() -> None:
    f = WaypointFollower(odom_only)
    f.set(SQUARE, 0, 0)
    _, trace = walk(f, Pose(0, 0, 0, 0), 90)
    assert f.active and f.laps_done >= 3
    assert all(laps == 0 for _, laps in trace)
    assert [i for i, _ in trace[:9]] == [0, 1, 2, 3, 0, 1, 2, 3, 0]
    assert "endless" in f.get()[1]


def test_use_z_waits_for_the_height() -> None:
    f = WaypointFollower(odom_only, FollowerConfig(z_tolerance=0.05))
    f.set([Waypoint("odom", 1, 0, 0.5, use_z=True), Waypoint("odom", 2, 0)], 1, 0)
    pose, _ = walk(f, Pose(0, 0, 0.3, 0), 10)  # flat floor at 0.3 m: never there
    assert f.active and f.current_index == 0 and "height 0.30 m" in f.status
    assert math.hypot(pose.x - 1, pose.y) < 0.01  # standing on the spot
    assert max(abs(v) for v in f.step(pose)) < 0.02
    # the same waypoint without use_z is passed at any height
    f.set([Waypoint("odom", 1, 0, 0.5), Waypoint("odom", 2, 0)], 1, 0)
    walk(f, Pose(0, 0, 0.3, 0), 20)
    assert not f.active and f.reached == 2
    # a ramp that reaches 0.5 m at x = 1: reached
    f.set([Waypoint("odom", 1, 0, 0.5, use_z=True)], 1, 0)
    walk(f, Pose(0, 0, 0.0, 0), 20, z_of=lambda x, y: 0.5 * min(x, 1.0))
    assert not f.active and f.reached == 1


def test_commands_respect_the_limits_and_head_for_the_goal() -> None:
    cfg = FollowerConfig(max_linear=0.5, max_lateral=0.2, max_angular=0.8)
    f = WaypointFollower(odom_only, cfg)
    f.set([Waypoint("odom", 10, 0)], 1, 0)
    assert f.step(Pose(0, 0, 0, 0)) == pytest.approx((0.5, 0.0, 0.0))
    vx, vy, wz = f.step(Pose(0, 0, 0, math.pi / 2))  # goal on the robot's right
    assert vx == pytest.approx(0.0, abs=1e-12) and vy == pytest.approx(-0.2)
    assert wz == pytest.approx(-0.8)
    vx, _, _ = f.step(Pose(9.9, 0, 0, 0))  # inside the slow-down distance: gain x distance
    assert vx == pytest.approx(0.1 * 0.5) or not f.active


def test_append_extends_or_restarts() -> None:
    f = WaypointFollower(odom_only)
    assert f.append(Waypoint("odom", 1, 0)) == (True, "waypoint appended at index 0")
    assert f.active and f.get()[3:] == (1, 0)
    walk(f, Pose(0, 0, 0, 0), 10)
    assert not f.active
    assert f.append(Waypoint("odom", 2, 0))[0]
    assert f.current_index == 1 and f.active  # walks on from the new one
    ok, msg = f.append(Waypoint("mars", 0, 0))
    assert not ok and msg == "waypoint 2: unknown frame 'mars'"


# -- gps --------------------------------------------------------------------------------------


def test_gps_along_the_equator_is_the_closed_form_ellipsoid() -> None:
    datum = GpsDatum(0.0, 0.0, 0.0)
    for dlon in (1e-4, 0.01, 1.0):
        x, y, z = datum.to_odom(0.0, dlon, 0.0)
        lam = math.radians(dlon)  # ECEF (a cos, a sin, 0) seen from (a, 0, 0)
        assert x == pytest.approx(A * math.sin(lam), rel=1e-12, abs=1e-9)
        assert y == pytest.approx(0.0, abs=1e-9)
        assert z == pytest.approx(A * math.cos(lam) - A, rel=1e-9, abs=1e-9)


def test_gps_along_the_meridian_is_the_closed_form_ellipsoid() -> None:
    datum = GpsDatum(0.0, 0.0, 0.0)
    for lat in (1e-4, 0.5, 10.0):
        phi = math.radians(lat)
        n = A / math.sqrt(1 - E2 * math.sin(phi) ** 2)
        x, y, z = datum.to_odom(lat, 0.0, 0.0)
        assert x == pytest.approx(0.0, abs=1e-9)
        assert y == pytest.approx(n * (1 - E2) * math.sin(phi), rel=1e-12)
        assert z == pytest.approx(n * math.cos(phi) - A, rel=1e-9, abs=1e-9)
    # not a flat-earth guess: 10 degrees north is 1,100 km off the sphere's arc, 105 m up
    assert datum.to_odom(10.0, 0.0, 0.0)[1] != pytest.approx(A * math.radians(10.0), rel=1e-3)


def test_gps_datum_heading_rotates_into_odom() -> None:
    east = GpsDatum(48.0, 11.0, 500.0)
    north_up = GpsDatum(48.0, 11.0, 500.0, heading=math.pi / 2)  # odom x points north
    e, n, u = east.to_odom(48.0001, 11.0001, 502.0)
    x, y, z = north_up.to_odom(48.0001, 11.0001, 502.0)
    assert (x, y, z) == pytest.approx((n, -e, u))
    assert n == pytest.approx(11.12, abs=0.02) and e == pytest.approx(7.45, abs=0.02)
    with pytest.raises(ValueError):
        GpsDatum(91.0, 0.0)


def test_follower_walks_gps_waypoints_through_the_datum() -> None:
    datum = GpsDatum(48.0, 11.0, 500.0)

    def resolve(wp: Waypoint) -> tuple[float, float, float]:
        return datum.to_odom(wp.x, wp.y, wp.z) if wp.frame == "gps" else odom_only(wp)

    f = WaypointFollower(resolve)
    target = Waypoint("gps", 48.00002, 11.00002, 500.0)
    f.set([target], 1, 0)
    pose, _ = walk(f, Pose(0, 0, 0, 0), 20)
    goal = datum.to_odom(48.00002, 11.00002, 500.0)
    assert not f.active and math.dist((pose.x, pose.y), goal[:2]) <= f.config.xy_tolerance
    assert goal[0] == pytest.approx(1.49, abs=0.01) and goal[1] == pytest.approx(2.22, abs=0.01)


# -- bad input (issue 22 item 20) -------------------------------------------------------------


def test_waypoints_far_beyond_any_walk_are_refused_and_nothing_changes() -> None:
    f = WaypointFollower(odom_only)
    assert f.set(SQUARE, 1, 0) == (True, SET_SUCCESS)
    for wp in (Waypoint("odom", 1e308, -1e308), Waypoint("odom", 0.0, 0.0, 2e4),
               Waypoint("odom", MAX_RANGE + 1.0, 0.0)):
        ok, msg = f.set([SQUARE[0], wp], 1, 0)
        assert not ok and msg.startswith("waypoint 1: ") and f"{MAX_RANGE:g} m" in msg, msg
        assert len(msg) < 150, msg
        ok, msg = f.append(wp)
        assert not ok and msg.startswith("waypoint 4: "), msg
    ok, msg = f.set([Waypoint("odom", 1e308, -1e308)], 1, 0)
    assert "(1e+308, -1e+308, 0.00)" in msg, msg
    assert f.waypoints == SQUARE and f.active
    assert f.set([Waypoint("odom", MAX_RANGE - 1.0, -MAX_RANGE + 1.0)], 1, 0)[0]
    # a resolver that puts an in-range waypoint far away (a far gps point) is refused too
    far = WaypointFollower(lambda wp: (wp.x * 1e6, wp.y, wp.z))
    ok, msg = far.set([Waypoint("odom", 100.0, 0.0)], 1, 0)
    assert (ok, msg) == (False, "waypoint 0: the point in odom (1e+08, 0.00, 0.00) must "
                         "lie within +-10000 m")


@pytest.mark.parametrize("lat, lon, why", [
    (95.0, 11.0, "latitude 95 is outside -90..90 deg"),
    (-90.5, 11.0, "latitude -90.5 is outside -90..90 deg"),
    (48.0, 181.0, "longitude 181 is outside -180..180 deg"),
])
def test_gps_latitude_and_longitude_must_be_on_the_earth(lat: float, lon: float,
                                                         why: str) -> None:
    datum = GpsDatum(48.0, 11.0, 500.0)
    f = WaypointFollower(lambda wp: datum.to_odom(wp.x, wp.y, wp.z))
    ok, msg = f.set([Waypoint("gps", lat, lon, 500.0)], 1, 0)
    assert (ok, msg) == (False, f"waypoint 0: gps {why}")
    with pytest.raises(ValueError, match=why):
        datum.to_odom(lat, lon, 500.0)


def test_stop_ends_an_endless_mission() -> None:
    f = WaypointFollower(odom_only)
    assert f.set(SQUARE, 0, 0) == (True, SET_SUCCESS)  # endless
    assert f.stop() == (True, STOPPED)
    assert not f.active and f.step(Pose(0.0, 0.0, 0.3, 0.0)) == (0.0, 0.0, 0.0)
    assert f.get() == (True, STOPPED, SQUARE, 0, 0)
    assert f.stop() == (True, "no waypoint mission is running")
    assert f.append(Waypoint("odom", 2, 2))[0] and f.active  # append walks on from it, once
