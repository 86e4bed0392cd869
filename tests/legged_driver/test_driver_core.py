"""LeggedDriverCore on a simulated clock: frames encoded with legged.dbc (as the lower computer
sends them) -> robot_state; services and their seed strings; body velocity commands on the bus,
closing the loop through an ideal base that integrates them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from lowerbase.clock import SimClock
from lowerbase.legged_driver.core import (
    MAP_SAVED,
    JoyListenType,
    LeggedDriverConfig,
    LeggedDriverCore,
    LocomotionState,
)
from lowerbase.legged_driver.pcdmap import make_cloud, read_pcd
from lowerbase.legged_driver.waypoints import (
    EMPTY,
    SET_SUCCESS,
    STOPPED,
    TIMEOUT,
    GpsDatum,
    Waypoint,
)
from lowerbase.protocol.legged import BODY_BUS, JOINT_NAMES, REPLY_PREFIX, legged_codec

CODEC = legged_codec()


class Rig:
    """The core, a simulated clock, and an ideal base that walks at the commanded velocity."""

    def __init__(self, config: LeggedDriverConfig | None = None) -> None:
        self.clock = SimClock()
        self.sent: list[tuple[int, int, bytes]] = []
        self.core = LeggedDriverCore(lambda b, i, d: self.sent.append((b, i, d)), self.clock,
                                     config)
        self.x = self.y = self.yaw = 0.0
        self.z = 0.3

    def body(self, name: str, bus: int = BODY_BUS, **signals: float) -> None:
        msg = CODEC.message(name)
        values = {s.name: 0 for s in msg.signal_sets[0]} | signals
        self.core.on_frame(bus, msg.frame_id, CODEC.encode(name, values))

    def publish_pose(self) -> None:
        self.body("BasePosition", X=self.x, Y=self.y, Z=self.z)
        h = self.yaw / 2
        self.body("BaseOrientation", QX=0.0, QY=0.0, QZ=math.sin(h), QW=math.cos(h))
        self.body("LocomotionStatus", State=7, LastRequest=15, FaultJoint=15)

    def run(self, seconds: float) -> None:
        dt = 1.0 / self.core.config.command_rate
        for _ in range(round(seconds / dt)):
            self.publish_pose()
            self.core.tick()
            _, s = CODEC.decode(*self.sent[-1][1:])
            vx, vy, wz = s["Vx"], s["Vy"], s["YawRate"]
            c, sn = math.cos(self.yaw), math.sin(self.yaw)
            self.x += (c * vx - sn * vy) * dt
            self.y += (sn * vx + c * vy) * dt
            self.yaw += wz * dt
            self.clock.advance(dt)


def test_frames_fill_robot_state() -> None:
    rig = Rig()
    for i in range(len(JOINT_NAMES)):
        bus, motor = divmod(i, 3)
        p = REPLY_PREFIX[motor + 1]
        rig.core.on_frame(bus, 0, CODEC.encode("MotorReply", {
            "MotorId": motor + 1, p + "Position": 0.1 * i, p + "Velocity": -1.0 * i / 4,
            p + "Torque": 0.5 * i, "Temperature": 30 + i, "Error": 1 if i == 5 else 0}))
    rig.body("BaseVelocity", Vx=0.4, Vy=-0.1, Vz=0.02)
    rig.body("BaseAngularVelocity", Wx=0.0, Wy=0.01, Wz=0.3)
    rig.body("BodyTemperature", Body=36.5, ActuatorMax=41.0, HottestJoint=11)
    rig.body("BmsPack", Voltage=50.4, Current=-6.2, Soc=80)
    rig.body("BmsCell", CellVoltageMax=4.2, CellVoltageMin=4.15, TempMax=30, TempMin=28)
    rig.x, rig.y, rig.yaw = 1.5, -2.0, 0.5
    rig.publish_pose()
    st = rig.core.robot_state()
    acts = st["actuator_states"]
    assert isinstance(acts, list) and [a["name"] for a in acts] == list(JOINT_NAMES)
    assert acts[4]["name"] == "FL_thigh"
    assert acts[4]["position"] == pytest.approx(0.4, abs=4e-4)
    assert acts[4]["velocity"] == pytest.approx(-1.0, abs=0.032)
    assert acts[4]["effort"] == pytest.approx(2.0, abs=0.014)
    assert (acts[4]["temperature"], acts[5]["status"], acts[4]["status"]) == (34, 1, 0)
    assert st["base_pos"] == pytest.approx([1.5, -2.0, 0.3], abs=1e-3)
    assert st["base_quat"] == pytest.approx([0, 0, math.sin(0.25), math.cos(0.25)], abs=1e-4)
    assert st["base_lin_vel"] == pytest.approx([0.4, -0.1, 0.02])
    assert st["base_ang_vel"] == pytest.approx([0.0, 0.01, 0.3])
    assert (st["voltage"], st["current"], st["max_voltage"], st["min_voltage"]) == \
        pytest.approx((50.4, -6.2, 4.2, 4.15))
    assert st["body_temperature"] == pytest.approx(36.5)
    assert st["state"] == LocomotionState.IN_CONTROL
    assert st["joy_listen_type"] == JoyListenType.VEL_CMD


def test_bad_frames_are_counted_not_raised() -> None:
    rig = Rig()
    rig.core.on_frame(0, 0x120, b"\x01")           # too short
    rig.core.on_frame(0, 0x7FF, b"\0" * 8)         # unknown ID
    rig.body("BmsPack", bus=2, Voltage=50.0)       # a body frame on a leg bus
    rig.core.on_frame(0, 0, b"\xff" * 8)            # MotorId 255: outside the catalog's range
    assert rig.core.stats["malformed"] == 3 and rig.core.stats["wrong_bus"] == 1
    assert rig.core.voltage == 0.0 and not rig.core.link_up


def test_services_answer_service_timeout_while_the_lower_computer_is_silent() -> None:
    rig = Rig()
    wp = [Waypoint("odom", 1, 0)]
    assert rig.core.set_waypoints(wp, 1, 0) == (False, TIMEOUT)
    assert rig.core.set_waypoints([], 1, 0) == (False, EMPTY)
    assert rig.core.append_waypoint(wp[0]) == (False, TIMEOUT)
    assert rig.core.get_waypoints()[:2] == (False, TIMEOUT)
    rig.publish_pose()
    assert rig.core.set_waypoints(wp, 1, 0) == (True, SET_SUCCESS)
    rig.clock.advance(0.6)  # link_timeout 0.5 s
    assert rig.core.get_waypoints()[:2] == (False, TIMEOUT)


def test_waypoint_loop_over_the_bus_with_laps() -> None:
    rig = Rig()
    rig.publish_pose()
    square = [Waypoint("odom", 2, 0), Waypoint("odom", 2, 2), Waypoint("odom", 0, 2),
              Waypoint("odom", 0, 0)]
    assert rig.core.set_waypoints(square, 2, 0) == (True, SET_SUCCESS)
    rig.run(10.0)
    ok, _, _, laps, index = rig.core.get_waypoints()
    assert ok and laps == 2 and index >= 1
    rig.run(80.0)
    assert rig.core.get_waypoints()[1:] == ("mission complete", square, 0, 3)
    assert rig.core.follower.reached == 8
    assert math.hypot(rig.x, rig.y) <= 0.15
    # every command went to the body bus as a BodyVelocityCommand; standing still at the end
    assert {(b, i) for b, i, _ in rig.sent} == {(BODY_BUS, 32)}
    assert rig.core.last_command == (0.0, 0.0, 0.0)


def test_joystick_takes_over_and_gives_back() -> None:
    rig = Rig()
    rig.publish_pose()
    rig.core.set_waypoints([Waypoint("odom", 10, 0)], 1, 0)
    rig.run(0.2)
    assert rig.core.last_command[0] > 0.5
    assert rig.core.set_listen("joy<&>app")[0]
    assert rig.core.robot_state()["joy_listen_type"] == JoyListenType.JOY
    assert not rig.core.set_listen("joy<&>intruder")[0]
    assert not rig.core.set_velocity(1.0, 0.0, 0.0)  # cmd_vel waits while the joystick holds
    rig.core.on_joy("joy", [0.0, -0.5, 0.0, 0.0])
    rig.run(0.2)
    assert rig.core.last_command == pytest.approx((-0.3, 0.0, 0.0), abs=1e-3)
    rig.run(1.0)  # no Joy for 0.5 s: stop
    assert rig.core.last_command == (0.0, 0.0, 0.0)
    assert rig.core.set_listen("joy<&><CLOSE>")[0]
    rig.run(0.1)
    assert rig.core.last_command[0] > 0.5  # the mission walks on
    assert rig.core.set_velocity(0.0, 0.2, 0.0)
    rig.run(0.1)
    assert rig.core.last_command == pytest.approx((0.0, 0.2, 0.0), abs=1e-3)


def test_set_map_saves_and_initialises_localization(tmp_path: Path) -> None:
    rig = Rig(LeggedDriverConfig(map_dir=tmp_path))
    rig.x, rig.y, rig.yaw = 1.0, 0.5, 0.3
    rig.publish_pose()
    pts = np.random.default_rng(1).uniform(-20, 20, (500, 3)).astype(np.float32)
    pose = (10.0, 20.0, 0.0, 0.0, 0.0, math.sin(0.6), math.cos(0.6))  # map yaw 1.2
    assert rig.core.set_map("office", make_cloud(pts), pose) == (True, MAP_SAVED)
    assert np.array_equal(read_pcd(tmp_path / "office.pcd"), pts.astype(np.float64))
    est = rig.core.pose_in_map()
    assert est is not None
    assert (est.x, est.y, est.yaw) == pytest.approx((10.0, 20.0, 1.2), abs=2e-3)
    # walk 1 m forward in odom: 1 m along the map heading in the map
    rig.x += math.cos(0.3)
    rig.y += math.sin(0.3)
    rig.publish_pose()
    est = rig.core.pose_in_map()
    assert est is not None
    assert (est.x, est.y) == pytest.approx((10 + math.cos(1.2), 20 + math.sin(1.2)), abs=2e-3)
    # a waypoint in the map's frame resolves back to the odom point it came from
    back = rig.core.resolve(Waypoint("office", est.x, est.y, 0.0))
    assert back[:2] == pytest.approx((rig.x, rig.y), abs=2e-3)
    ok, msg = rig.core.set_waypoints([Waypoint("warehouse", 0, 0)], 1, 0)
    assert not ok and "unknown frame 'warehouse'" in msg and "'office'" in msg


def test_set_map_refusals() -> None:
    rig = Rig(LeggedDriverConfig(mapping_plugin=False))
    rig.publish_pose()
    cloud = make_cloud(np.zeros((3, 3)))
    assert rig.core.set_map("m", cloud, (0, 0, 0, 0, 0, 0, 1)) == (False, TIMEOUT)
    rig = Rig()
    rig.publish_pose()
    assert rig.core.set_map("../etc", cloud, (0, 0, 0, 0, 0, 0, 1))[0] is False
    assert rig.core.set_map("m", object(), (0, 0, 0, 0, 0, 0, 1)) == (
        False, "Map not saved: not a PointCloud2: 'object' object has no attribute 'height'")
    ok, msg = rig.core.set_map("m", cloud, (0, 0, math.nan, 0, 0, 0, 1))
    assert not ok and "finite" in msg and rig.core.laser_map is None


def test_set_map_refuses_a_zero_quaternion_and_bad_clouds(tmp_path: Path) -> None:
    """Issue 22 item 21: each answered "Map saved." before; now success false, "Map not
    saved: " and the reason, nothing written, no map loaded."""
    rig = Rig(LeggedDriverConfig(map_dir=tmp_path))
    rig.publish_pose()
    good = make_cloud(np.array([[1.0, 2.0, 0.0], [3.0, -1.0, 0.5]]))
    ok, msg = rig.core.set_map("m", good, (0, 0, 0, 0, 0, 0, 0))
    assert (ok, msg) == (False, "Map not saved: initial_pose orientation (0, 0, 0, 0) is not "
                                "a rotation (norm 0): send a unit quaternion, e.g. (0, 0, 0, 1)")
    count0 = make_cloud(np.zeros((3, 3)))
    count0.fields[0].count = 0
    noise = make_cloud(np.zeros((1000, 3)))
    noise.data = np.random.default_rng(3).bytes(12000)  # 12 kB of random bytes
    for cloud, why in ((count0, "count 0"), (noise, "beyond")):
        ok, msg = rig.core.set_map("m", cloud, (0, 0, 0, 0, 0, 0, 1))
        assert not ok and msg.startswith("Map not saved: ") and why in msg, msg
        assert "\n" not in msg and len(msg) < 200
    assert rig.core.laser_map is None and list(tmp_path.iterdir()) == []
    # a quaternion that is not unit length (but a rotation) is normalised, as tf does
    assert rig.core.set_map("m", good, (0, 0, 0, 0, 0, 1, 1)) == (True, MAP_SAVED)
    est = rig.core.pose_in_map()
    assert est is not None and est.yaw == pytest.approx(math.pi / 2)


def test_gps_waypoints_need_a_datum() -> None:
    rig = Rig()
    rig.publish_pose()
    ok, msg = rig.core.set_waypoints([Waypoint("gps", 48.0, 11.0, 500.0)], 1, 0)
    assert not ok and "gps datum" in msg
    assert "~gps_origin" in msg and "~gps_datum" not in msg  # the parameter's real name
    rig = Rig(LeggedDriverConfig(gps_datum=GpsDatum(48.0, 11.0, 500.0)))
    rig.publish_pose()
    assert rig.core.set_waypoints([Waypoint("gps", 48.00001, 11.0, 500.0)], 1, 0)[0]
    rig.run(10.0)
    assert rig.y == pytest.approx(1.11, abs=0.15) and not rig.core.follower.active


def test_locomotion_request_frame() -> None:
    rig = Rig()
    rig.core.request_state(LocomotionState.STANDING_MODE)
    bus, frame_id, data = rig.sent[-1]
    assert (bus, frame_id) == (BODY_BUS, 16)
    assert CODEC.decode(frame_id, data)[1]["Request"] == 6


def test_stop_waypoints_ends_an_endless_mission_and_the_robot_stops() -> None:
    rig = Rig()
    rig.publish_pose()
    square = [Waypoint("odom", 1, 0), Waypoint("odom", 1, 1)]
    assert rig.core.set_waypoints(square, 0, 0) == (True, SET_SUCCESS)  # endless
    rig.run(0.5)
    assert rig.core.last_command[0] > 0.1
    assert rig.core.stop_waypoints() == (True, STOPPED)
    rig.run(0.1)
    assert rig.core.last_command == (0.0, 0.0, 0.0)
    assert rig.core.get_waypoints() == (True, STOPPED, square, 0, 0)


def test_robot_state_shows_a_silent_lower_computer_within_the_link_timeout() -> None:
    """Issue 22 item 4: robot_state kept its last values at 50 Hz after the lower computer
    was gone; past link_timeout (0.5 s) it says COMM_DISABLED with zero velocities."""
    from lowerbase.protocol.legged import LocomotionState
    from lowerbase.simloop.legged import LeggedSimLoop

    loop = LeggedSimLoop()
    loop.set_goal(LocomotionState.STANDING_MODE)
    loop.run(6.0)
    up = loop.driver.robot_state()
    assert up["state"] == int(LocomotionState.STANDING_MODE), up["state"]
    loop.clock.advance(0.45)  # silent, within the timeout: still the last state
    assert loop.driver.robot_state()["state"] == int(LocomotionState.STANDING_MODE)
    loop.clock.advance(0.1)  # 0.55 s without a body frame
    gone = loop.driver.robot_state()
    assert gone["state"] == int(LocomotionState.COMM_DISABLED)
    assert gone["base_lin_vel"] == [0.0, 0.0, 0.0] and gone["base_ang_vel"] == [0.0, 0.0, 0.0]
    assert gone["base_pos"] == up["base_pos"]
    loop.run(0.1)  # heard again
    assert loop.driver.robot_state()["state"] == int(LocomotionState.STANDING_MODE)
    loop.close()
