"""legged_driver as a ROS node, black-box: a real rosmaster, `lowerbase driver --robot legged` in
a process of its own on four udp_multicast leg buses, a scripted lower computer on those buses
(tests.legged_driver.legged_ros.ScriptedLegs), the seed's services called with rospy service proxies
from the test process and robot_state read by the driver tests' probe node (rospy.init_node
works once per process, so the test process stays a plain client). The pure parts (settings,
bus layout, the locomotion goal's path) are tested first."""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from lowerbase.errors import ConfigError
from lowerbase.legged.body import ALLOWED
from lowerbase.legged_driver.goals import next_request
from lowerbase.legged_driver.node import (
    leg_bus_configs,
    load_legged_settings,
    lower_ids,
)
from lowerbase.legged_driver.waypoints import EMPTY, SET_SUCCESS, STOPPED, TIMEOUT
from lowerbase.protocol.legged import JOINT_NAMES, LocomotionState
from tests.conftest import TEST_GROUP, Proc, bus_cli_args, free_udp_port
from tests.driver.conftest import RosMaster
from tests.driver.test_node_ros import PROBE, Probe
from tests.legged_driver.legged_ros import (  # noqa: F401 (fixtures)
    ScriptedLegs,
    legged_build,
    legged_master,
    legged_msgs,
    legged_srvs,
)

S = LocomotionState

# -- pure parts ---------------------------------------------------------------------------------


def test_the_goal_path_follows_the_state_table_and_never_drops_the_robot() -> None:
    for goal in (S.IN_CONTROL, S.STANDING_MODE):
        for start in S:
            state, seen = start, [start]
            for _ in range(12):
                want = next_request(state, goal)
                if want is None:
                    if state in (S.MOTOR_COMMUTATION, S.SITDOWN_MODE):
                        state = S.MOTOR_ENABLED  # automatic
                        continue
                    break
                assert want in ALLOWED[state], (start, state, want)
                assert want not in (S.MOTOR_DISABLED, S.COMM_DISABLED)
                state = want
                seen.append(state)
            assert state == goal, (start, goal, seen)
    assert [next_request(s, S.SITDOWN_MODE) for s in (S.IN_CONTROL, S.STANDING_MODE)] == [
        S.STANDING_MODE, S.SITDOWN_MODE]
    assert next_request(S.COMM_ENABLED, S.SITDOWN_MODE) is None  # not up: nothing to do
    assert next_request(S.MOTOR_COMMUTATION, S.IN_CONTROL) is None  # wait for it


def test_settings_defaults_and_bad_values(tmp_path: Path) -> None:
    settings, config = load_legged_settings({}, ros_home=tmp_path)
    assert settings.topics == {"robot_state": "robot_state", "cmd_vel": "/cmd_vel"}
    assert settings.services["set_waypoints"] == "planning/set_waypoints"
    assert config.mapping_plugin and config.gps_datum is None
    assert config.map_dir == tmp_path / "maps"
    _, config = load_legged_settings({"gps_origin": [31.2, 121.5, 4.0], "mapping_plugin": False,
                                      "map_dir": str(tmp_path)})
    assert config.gps_datum is not None and config.gps_datum.altitude == 4.0
    assert not config.mapping_plugin and config.map_dir == tmp_path
    for params, match in (({"gps_origin": [91.0, 0.0]}, "~gps_origin"),
                          ({"gps_origin": "here"}, "~gps_origin"),
                          ({"mapping_plugin": "no"}, "~mapping_plugin"),
                          ({"publish_rate": 0}, "~publish_rate"),
                          ({"topics": {"odom": "/x"}}, "~topics"),
                          ({"namespace": "x"}, "unknown parameter")):
        with pytest.raises(ConfigError, match=match) as info:
            load_legged_settings(params)
        assert "\n" not in str(info.value)


def test_four_leg_buses_from_one_bus_option() -> None:
    udp = {"interface": "udp_multicast", "channel": "239.74.163.2", "port": 43113}
    assert [c["port"] for c in leg_bus_configs(udp)] == [43113, 43114, 43115, 43116]
    assert [c["channel"] for c in leg_bus_configs({"interface": "virtual", "channel": "v"})] \
        == ["v/0", "v/1", "v/2", "v/3"]
    socketcan = leg_bus_configs({"interface": "socketcan", "channel": "can0,can1,can2,can3"})
    assert [c["channel"] for c in socketcan] == ["can0", "can1", "can2", "can3"]
    with pytest.raises(ConfigError, match="four channels"):
        leg_bus_configs({"interface": "socketcan", "channel": "can0"})
    with pytest.raises(ConfigError, match="lower port"):
        leg_bus_configs({**udp, "port": 65534})
    assert lower_ids() == [0, 128, 144, 272, 273, 288, 289, 320, 768, 769, 770, 771, 772]


def test_cli_errors_are_one_line(capsys: pytest.CaptureFixture[str],
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    from lowerbase.cli import main

    assert main(["driver", "--robot", "legged", "--replay", "run.blf"]) == 1
    assert "--replay is for the wheeled robot" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "lowerbase_legged_msgs", None)
    assert main(["driver", "--robot", "legged"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ("lowerbase_legged_msgs is not generated" in err
                                      or "ROS is not installed" in err)
    monkeypatch.setitem(sys.modules, "rospy", None)
    assert main(["driver", "--robot", "legged"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("lowerbase driver: error: ROS is not installed") and \
        err.count("\n") == 1


# -- the node -----------------------------------------------------------------------------------


class Rig:
    def __init__(self, master: RosMaster, tmp: Path, name: str, *params: str) -> None:
        self.bus = {"interface": "udp_multicast", "channel": TEST_GROUP, "port": free_udp_port(),
                    "hop_limit": 0}
        self.legs = ScriptedLegs(leg_bus_configs(self.bus))
        self.map_dir = tmp / name
        node_env = {k: v for k, v in master.env.items() if k != "ROS_IP"}
        self.node = Proc(["driver", "--robot", "legged", *bus_cli_args(self.bus),
                          f"__name:={name}", f"_map_dir:={self.map_dir}", *params], node_env)
        try:
            self.node.wait_for("on ROS master", timeout=30.0)
        except AssertionError:
            self.close()
            raise

    def close(self) -> None:
        self.node.stop()
        self.legs.close()


@pytest.fixture(scope="module")
def rig(legged_master: RosMaster, tmp_path_factory: pytest.TempPathFactory  # noqa: F811
        ) -> Iterator[dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("legged_node")
    saved = {k: os.environ.get(k) for k in legged_master.env}
    os.environ.update(legged_master.env)  # the test process's rospy clients use this master
    rigs: list[Rig] = []
    probe: Probe | None = None
    try:
        rigs.append(Rig(legged_master, tmp, "legged_driver"))
        script = tmp / "probe.py"
        script.write_text(PROBE)
        probe = Probe(script, legged_master.env,
                      {"/robot_state": "lowerbase_legged_msgs/RobotState",
                       "/real/robot_state": "lowerbase_legged_msgs/RobotState"})
        yield {"rig": rigs[0], "probe": probe, "master": legged_master, "tmp": tmp,
               "rigs": rigs}
    finally:
        if probe is not None:
            probe.close()
        for r in rigs:
            r.close()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def call(service: str, cls: Any, /, **args: Any) -> Any:
    import rospy

    rospy.wait_for_service(service, timeout=10.0)
    return rospy.ServiceProxy(service, cls)(**args)


def state_of(probe: Probe) -> dict[str, Any]:
    msg: dict[str, Any] = probe.ask(op="stats")["/robot_state"]["msg"]
    return msg


@pytest.mark.ros
@pytest.mark.process
def test_robot_state_carries_the_lower_computer(rig: dict[str, Any]) -> None:
    probe: Probe = rig["probe"]
    probe.wait_for(lambda s: s["/robot_state"]["msg"]["voltage"] > 0, 20.0, "robot_state")
    types = probe.ask(op="types")
    assert types["/robot_state"] == "lowerbase_legged_msgs/RobotState"
    st = state_of(probe)
    acts = st["actuator_states"]
    assert [a["name"] for a in acts] == list(JOINT_NAMES)
    assert [a["position"] for a in acts] == pytest.approx([0.05 * i for i in range(12)],
                                                          abs=4e-4)
    assert [a["temperature"] for a in acts] == [30 + i for i in range(12)]
    assert all(a["status"] == 0 for a in acts)
    assert (st["voltage"], st["current"], st["max_voltage"], st["min_voltage"]) == \
        pytest.approx((50.4, -3.0, 4.2, 4.1), abs=0.01)
    assert st["body_temperature"] == pytest.approx(36.5, abs=0.1)
    assert st["base_pos"][2] == pytest.approx(0.3, abs=1e-3)
    assert st["joy_listen_type"] == 1  # VEL_CMD: the node listens to /cmd_vel


@pytest.mark.ros
@pytest.mark.process
def test_walk_service_brings_the_robot_to_in_control(rig: dict[str, Any]) -> None:
    from std_srvs.srv import Trigger  # type: ignore[import-untyped]

    probe: Probe = rig["probe"]
    reply = call("/legged_driver/walk", Trigger)
    assert reply.success and reply.message.endswith("-> IN_CONTROL")
    probe.wait_for(lambda s: s["/robot_state"]["msg"]["state"] == S.IN_CONTROL, 20.0,
                   "IN_CONTROL")
    legs: ScriptedLegs = rig["rig"].legs
    with legs.lock:
        requests = list(legs.requests)
    path = [S.COMM_ENABLED, S.MOTOR_READY, S.MOTOR_ENABLED, S.STANDING_MODE, S.IN_CONTROL]
    assert [r for i, r in enumerate(requests) if i == 0 or r != requests[i - 1]] == path


@pytest.mark.ros
@pytest.mark.process
def test_waypoints_are_walked(rig: dict[str, Any], legged_msgs: ModuleType,  # noqa: F811
                              legged_srvs: ModuleType) -> None:  # noqa: F811
    probe: Probe = rig["probe"]
    probe.wait_for(lambda s: s["/robot_state"]["msg"]["state"] == S.IN_CONTROL, 30.0,
                   "IN_CONTROL (the walk test runs first)")
    reply = call("/planning/set_waypoints", legged_srvs.SetWaypoints, waypoints=[],
                 repetition=1, current_index=0)
    assert (reply.success, reply.message) == (False, EMPTY)
    Wp = legged_msgs.Waypoint
    wps = [Wp(frame="odom", x=0.6, y=0.0, z=0.0, use_z=False),
           Wp(frame="odom", x=0.6, y=0.4, z=0.0, use_z=False)]
    reply = call("/planning/set_waypoints", legged_srvs.SetWaypoints, waypoints=wps,
                 repetition=3, current_index=1)
    assert (reply.success, reply.message) == (True, SET_SUCCESS)
    got = call("/planning/get_waypoints", legged_srvs.GetWaypoints)
    assert got.success and [(w.frame, w.x, w.y) for w in got.waypoints] == [
        ("odom", 0.6, 0.0), ("odom", 0.6, 0.4)]
    assert (got.repetition, got.current_index) == (3, 1)
    # the robot walks toward waypoint 1 first, then 0: the base position moves there
    probe.wait_for(lambda s: math.dist(s["/robot_state"]["msg"]["base_pos"][:2], (0.6, 0.4))
                   < 0.15, 30.0, "the base at waypoint 1")
    got = call("/planning/get_waypoints", legged_srvs.GetWaypoints)
    assert got.current_index == 0 or got.repetition < 3
    reply = call("/planning/append_waypoint", legged_srvs.AppendWaypoint,
                 waypoint=Wp(frame="nowhere", x=0.0, y=0.0, z=0.0, use_z=False))
    assert not reply.success and "unknown frame 'nowhere'" in reply.message
    # stop the mission (one lap from a waypoint it is at) so later tests start from rest
    call("/planning/set_waypoints", legged_srvs.SetWaypoints, waypoints=[wps[0]],
         repetition=1, current_index=0)


@pytest.mark.ros
@pytest.mark.process
def test_an_endless_mission_is_stopped_by_stop_waypoints(
        rig: dict[str, Any], legged_msgs: ModuleType,  # noqa: F811
        legged_srvs: ModuleType) -> None:  # noqa: F811
    """The seed has no call that ends a mission and refuses an empty list: ~stop_waypoints
    (std_srvs/Trigger) ends an endless one and the robot is sent zero velocity."""
    from std_srvs.srv import Trigger  # type: ignore[import-untyped]

    probe: Probe = rig["probe"]
    legs: ScriptedLegs = rig["rig"].legs
    Wp = legged_msgs.Waypoint
    wps = [Wp(frame="odom", x=0.0, y=0.0, z=0.0, use_z=False),
           Wp(frame="odom", x=0.6, y=0.0, z=0.0, use_z=False)]
    reply = call("/planning/set_waypoints", legged_srvs.SetWaypoints, waypoints=wps,
                 repetition=0, current_index=0)
    assert (reply.success, reply.message) == (True, SET_SUCCESS)

    def last_command() -> tuple[float, float, float]:
        with legs.lock:
            return legs.commands[-1] if legs.commands else (0.0, 0.0, 0.0)

    probe.wait_for(lambda s: any(abs(v) > 0.05 for v in last_command()), 20.0,
                   "the endless mission walking")
    reply = call("/legged_driver/stop_waypoints", Trigger)
    assert (reply.success, reply.message) == (True, STOPPED)
    got = call("/planning/get_waypoints", legged_srvs.GetWaypoints)
    assert (got.message, got.repetition, len(got.waypoints)) == (STOPPED, 0, 2)
    probe.wait_for(lambda s: last_command() == (0.0, 0.0, 0.0), 20.0, "zero velocity")
    reply = call("/legged_driver/stop_waypoints", Trigger)
    assert (reply.success, reply.message) == (True, "no waypoint mission is running")


@pytest.mark.ros
@pytest.mark.process
def test_set_listen_hands_the_joystick_over_and_back(rig: dict[str, Any]) -> None:
    from lowerbase_legged_msgs.srv import SetListen

    probe: Probe = rig["probe"]
    legs: ScriptedLegs = rig["rig"].legs
    reply = call("/set_listen", SetListen, data="/<&>x")  # rospy logged FATAL on it
    assert not reply.success and "is not a ROS topic name" in reply.message
    reply = call("/set_listen", SetListen, data="joy<&>my_app")
    assert reply.success, reply.message
    reply = call("/set_listen", SetListen, data="joy<&>other_app")
    assert not reply.success and "my_app" in reply.message
    probe.wait_for(lambda s: s["/robot_state"]["msg"]["joy_listen_type"] == 0, 10.0, "JOY")
    probe.ask(op="publish", topic="/joy", type="sensor_msgs/Joy",
              fields={"": {"axes": [0.0, 0.5, 0.0, 0.0]}}, rate=20.0, duration=2.0)

    def joy_drives() -> bool:
        with legs.lock:
            return bool(legs.commands) and legs.commands[-1][0] == pytest.approx(0.3, abs=0.01)

    probe.wait_for(lambda s: joy_drives(), 10.0, "vx 0.3 m/s (half the 0.6 m/s stick) on the bus")
    reply = call("/set_listen", SetListen, data="joy<&><CLOSE>")
    assert reply.success, reply.message
    probe.wait_for(lambda s: s["/robot_state"]["msg"]["joy_listen_type"] == 1, 10.0, "VEL_CMD")


def _cloud(points: np.ndarray) -> Any:
    from sensor_msgs.msg import PointCloud2, PointField

    xyz = np.asarray(points, dtype="<f4")
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, n in enumerate("xyz")]
    return PointCloud2(height=1, width=len(xyz), fields=fields, is_bigendian=False,
                       point_step=12, row_step=12 * len(xyz), data=xyz.tobytes(), is_dense=True)


@pytest.mark.ros
@pytest.mark.process
def test_set_map_saves_the_map_or_times_out_without_the_plugin(
        rig: dict[str, Any], legged_srvs: ModuleType) -> None:  # noqa: F811
    from geometry_msgs.msg import Point, Pose, Quaternion

    from lowerbase.legged_driver.pcdmap import read_pcd

    points = np.array([[1.0, 2.0, 0.0], [3.0, -1.0, 0.5], [0.0, 0.0, 2.0]])
    pose = Pose(position=Point(1.0, 2.0, 0.0), orientation=Quaternion(0.0, 0.0, 0.0, 1.0))
    reply = call("/set_map", legged_srvs.SetLaserMap, name="lab", pc=_cloud(points),
                 initial_pose=pose)
    assert (reply.success, reply.message) == (True, "Map saved.")
    assert read_pcd(rig["rig"].map_dir / "lab.pcd") == pytest.approx(points)
    # a second robot whose mapping plugin is off, in a namespace of its own
    nomap = Rig(rig["master"], rig["tmp"], "nomap", "__ns:=nomap", "_mapping_plugin:=false",
                "_gps_origin:=[31.2,121.5,4.0]")
    rig["rigs"].append(nomap)
    deadline = time.monotonic() + 20.0  # until the node hears its lower computer
    while not call("/nomap/planning/get_waypoints", legged_srvs.GetWaypoints).success:
        assert time.monotonic() < deadline, "the nomap node never heard its lower computer"
        time.sleep(0.1)
    reply = call("/nomap/set_map", legged_srvs.SetLaserMap, name="lab", pc=_cloud(points),
                 initial_pose=pose)
    assert (reply.success, reply.message) == (False, TIMEOUT)
    assert not (nomap.map_dir / "lab.pcd").exists()
    # ~gps_origin came through the command line: gps waypoints are accepted (refused without)
    from lowerbase_legged_msgs.msg import Waypoint as Wp

    gps = [Wp(frame="gps", x=31.2001, y=121.5, z=4.0, use_z=False)]
    reply = call("/nomap/planning/set_waypoints", legged_srvs.SetWaypoints, waypoints=gps,
                 repetition=1, current_index=0)
    assert (reply.success, reply.message) == (True, SET_SUCCESS)
    reply = call("/planning/set_waypoints", legged_srvs.SetWaypoints, waypoints=gps,
                 repetition=1, current_index=0)
    assert not reply.success and "gps datum" in reply.message


@pytest.mark.ros
@pytest.mark.process
def test_against_the_legged_emulator(rig: dict[str, Any], legged_srvs: ModuleType  # noqa: F811
                                     ) -> None:
    """The real lower computer (`lowerbase emulate --robot legged`), when it is installed:
    ~walk reaches IN_CONTROL and the robot walks to a waypoint."""
    pytest.importorskip("lowerbase.legged.emulate", reason="the legged emulator is not built")
    from lowerbase_legged_msgs.msg import Waypoint as Wp
    from std_srvs.srv import Trigger  # type: ignore[import-untyped]

    master: RosMaster = rig["master"]
    bus = {"interface": "udp_multicast", "channel": TEST_GROUP, "port": free_udp_port(),
           "hop_limit": 0}
    emulator = Proc(["emulate", "--robot", "legged", *bus_cli_args(bus)], master.env)
    node = Proc(["driver", "--robot", "legged", *bus_cli_args(bus), "__ns:=real",
                 f"_map_dir:={rig['tmp'] / 'real'}"],
                {k: v for k, v in master.env.items() if k != "ROS_IP"})
    try:
        emulator.wait_for("Ctrl-C stops", timeout=30.0)
        node.wait_for("on ROS master", timeout=30.0)
        deadline = time.monotonic() + 20.0
        while not (reply := call("/real/legged_driver/walk", Trigger)).success:
            assert time.monotonic() < deadline, reply.message
            time.sleep(0.1)
        goal = (0.5, 0.0)
        deadline = time.monotonic() + 30.0
        while True:
            reply = call("/real/planning/set_waypoints", legged_srvs.SetWaypoints,
                         waypoints=[Wp(frame="odom", x=goal[0], y=goal[1], z=0.0, use_z=False)],
                         repetition=1, current_index=0)
            if reply.success:
                break
            assert time.monotonic() < deadline, reply.message
            time.sleep(0.2)
        probe: Probe = rig["probe"]
        stats = probe.wait_for(lambda s: s["/real/robot_state"]["msg"]["state"] == S.IN_CONTROL
                               and math.dist(s["/real/robot_state"]["msg"]["base_pos"][:2],
                                             goal) < 0.15, 60.0, "the emulated robot at 0.5, 0")
        st = stats["/real/robot_state"]["msg"]
        assert [a["name"] for a in st["actuator_states"]] == list(JOINT_NAMES)
        assert st["voltage"] > 0 and st["body_temperature"] > 0
    finally:
        node.stop()
        emulator.stop()
