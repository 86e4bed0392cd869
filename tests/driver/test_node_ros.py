"""driver_base as a ROS node: a real rosmaster, the emulator and the node in processes of their
own, checked at the topic level by a probe node (a helper subprocess: rospy.init_node works once
per process, so the test process itself stays ROS-free) and by rostopic, rosbag and roslaunch.

One master, emulator, node and probe serve the whole module; each test waits on conditions with
deadlines. The pure parts (settings, conversions, throttle, CLI errors) are tested first.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import random
import select
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from lowerbase.cli import main
from lowerbase.driver.settings import DEFAULT_TOPICS, load_settings
from lowerbase.errors import ConfigError
from lowerbase.firmware_model.profile import load_profile
from tests.conftest import ROOT, TEST_GROUP, Proc, bus_cli_args, free_udp_port

DRIVER_DIR = ROOT / "lowerbase" / "driver"
LAUNCH = DRIVER_DIR / "launch" / "driver_base.launch"
CONFIG = DRIVER_DIR / "config" / "driver_base.yaml"

#: [s] every wait below is for something to happen, and returns when it does: a bound against
#: a hang sized for a busy CI host (beside 12 busy processes a 5 s bound failed), not a speed
BOUND = 90.0

#: topic -> type the node must publish (vendor names: seed 000, woosh_msgs)
PUBLISHED = {
    "/odom_raw": "nav_msgs/Odometry",
    "/odom": "nav_msgs/Odometry",
    "/imu/data_raw": "sensor_msgs/Imu",
    "/odom_twist": "geometry_msgs/Twist",
    "/odometer": "std_msgs/Float64",
    "/battery": "woosh_msgs/Battery",
    "/driver_base/bms": "woosh_msgs/BMS",
    "/driver_base/parameter": "woosh_msgs/Parameter",
    "/information": "woosh_msgs/Information",
    "/status_code": "std_msgs/UInt64",
    "/driver_base/link_state": "std_msgs/String",
    "/tf": "tf2_msgs/TFMessage",
}
SUBSCRIBED = {
    "/base_cmd_vel": "geometry_msgs/Twist",
    "/smooth_cmd_vel": "geometry_msgs/Twist",
    "/rgbled": "woosh_msgs/LED",
    "/rgbled_shelf": "woosh_msgs/LED",
    "/kShelfLedColorPubName": "woosh_msgs/LED",
}
#: what the probe also listens to: the launched and the replaying node, in namespaces
EXTRA = {
    "/launched/driver_base/link_state": "std_msgs/String",
    "/launched/odom": "nav_msgs/Odometry",
    "/replay/odom": "nav_msgs/Odometry",
    "/replay/odom_twist": "geometry_msgs/Twist",
}


# -- pure parts -----------------------------------------------------------------------------


def test_settings_defaults_follow_the_vendor_names() -> None:
    settings, config = load_settings({})
    assert settings.topics == DEFAULT_TOPICS
    assert settings.topics["odom_twist"] == "odom_twist"  # relative, as in the seed
    assert settings.topics["battery"] == "/battery"
    assert (settings.odom_frame, settings.base_frame, settings.publish_tf) == (
        "odom", "base_link", True)
    assert config.command_rate == 50.0 and config.gyro_sigma is None


def test_settings_file_lists_every_default() -> None:
    import yaml

    params = yaml.safe_load(CONFIG.read_text())
    assert load_settings(params) == load_settings({})


@pytest.mark.parametrize(("params", "match"), [
    ({"odom_frame": "/odom"}, "~odom_frame"),
    ({"topics": {"odom": 3}}, "~topics/odom"),
    ({"topics": {"nonsense": "/x"}}, "unknown key"),
    ({"rates": {"imu": -1}}, "~rates/imu"),
    ({"command_rate": 0.0}, "~command_rate must be > 0"),
    ({"command_rate": "fast"}, "~command_rate"),
    ({"publish_tf": "yes"}, "~publish_tf"),
    ({"odometry_noise": {"scale_error": -1.0}}, "~odometry_noise"),
    ({"wheel_radius": 0.1}, "unknown parameter"),
])
def test_settings_reject_bad_values_in_one_line(params: dict[str, Any], match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        load_settings(params)
    assert "\n" not in str(info.value)


def test_throttle_keeps_the_average_rate_despite_jitter() -> None:
    import random

    from lowerbase.driver.node import Throttle

    rng = random.Random(3)
    for source_hz, rate, expected in ((50.0, 50.0, 50), (100.0, 10.0, 10), (50.0, 0.0, 50)):
        throttle = Throttle(rate)
        passed = sum(throttle.ready(k / source_hz + rng.uniform(-0.003, 0.003))
                     for k in range(int(10 * source_hz)))
        assert abs(passed / 10.0 - expected) <= 1.0, (source_hz, rate, passed)


def test_conversions(woosh_msgs: Any) -> None:
    from lowerbase.driver import ros_io

    odom = ros_io.odometry_msg(0, "odom", "base_link", (1.0, 2.0, math.pi / 2), (0.5, 0.1),
                               [1, 2, 3, 2, 4, 5, 3, 5, 6], [7, 8, 8, 9], 1e6)
    q = odom.pose.pose.orientation
    assert (q.z, q.w) == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)))
    cov = odom.pose.covariance
    assert (cov[0], cov[1], cov[5], cov[35], cov[14]) == (1, 2, 3, 6, 1e6)
    tcov = odom.twist.covariance
    assert (tcov[0], tcov[5], tcov[30], tcov[35], tcov[7]) == (7, 8, 8, 9, 7)  # vy as sure as vx
    tf = ros_io.transform_from_odometry(odom)
    assert (tf.header.frame_id, tf.child_frame_id, tf.transform.translation.y) == (
        "odom", "base_link", 2.0)
    imu = ros_io.imu_msg(0, "base_link", (0.1, 0.2, 0.3), (0.0, 0.0, 9.8), 1e-4, 0.04)
    assert imu.orientation_covariance[0] == -1.0  # REP-145: no orientation
    assert imu.angular_velocity.z == 0.3 and imu.linear_acceleration_covariance[8] == 0.04
    p = load_profile().chassis
    params = {"wheelPerimeter": p.wheel_perimeter, "wheelDistant": p.wheel_distant,
              "ratioLeft": 20.0, "ratioRight": 20.0, "pulsePerCircle": 9999.6, "maxRPM": 3000.0,
              "minSpeed": 0.005, "maxLinear": 1.2, "maxAngular": 1.0, "joystickMaxLinear": 0.6,
              "joystickMaxAngular": 0.8, "maxSpeed": 1.5, "commandTimeout": 0.5}
    assert ros_io.parameter_complete(params)
    msg = ros_io.parameter_msg(0, params)
    assert msg.pulsePerCircle == 10000 and msg.wheelPerimeter == p.wheel_perimeter
    assert ros_io.twist_args(ros_io.twist_msg(0.3, -0.2)) == (0.3, -0.2)
    assert ros_io.led_args(woosh_msgs.LED(submodule=2, color=0xFF00FF)) == {
        "submodule": 2, "urgency": 0, "abnormal": 0, "normal": 0, "color": 0xFF00FF}
    assert ros_io.status_code_msg(2**64 - 1).data == 2**64 - 1


def test_cli_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                 monkeypatch: pytest.MonkeyPatch, woosh_msgs: Any) -> None:
    assert main(["driver", "--replay", str(tmp_path / "missing.log")]) == 1
    assert capsys.readouterr().err.strip() == (
        f"lowerbase driver: error: --replay: no such file: {tmp_path / 'missing.log'}")
    (tmp_path / "run.txt").write_text("x")
    assert main(["driver", "--replay", str(tmp_path / "run.txt")]) == 1
    assert "not a python-can log" in capsys.readouterr().err
    assert main(["driver", "stray"]) == 1
    assert "unexpected argument 'stray'" in capsys.readouterr().err
    monkeypatch.setenv("ROS_MASTER_URI", f"http://127.0.0.1:{free_udp_port()}")
    assert main(["driver", "__name:=x"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("lowerbase driver: error: no ROS master at http://127.0.0.1:")
    assert err.count("\n") == 1


def test_cli_says_when_ros_is_missing(capsys: pytest.CaptureFixture[str],
                                      monkeypatch: pytest.MonkeyPatch, woosh_msgs: Any) -> None:
    monkeypatch.delitem(sys.modules, "lowerbase.driver.ros_io", raising=False)
    monkeypatch.setitem(sys.modules, "rospy", None)
    assert main(["driver"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("lowerbase driver: error: ROS is not installed")
    assert "venv --system-site-packages" in err and "/opt/ros/noetic/setup.bash" in err
    assert "make" not in err.split() and err.count("\n") == 1  # pip users have no Makefile
    monkeypatch.undo()
    import lowerbase.driver

    monkeypatch.delitem(sys.modules, "lowerbase.driver.ros_io", raising=False)
    monkeypatch.delattr(lowerbase.driver, "ros_io", raising=False)
    monkeypatch.setitem(sys.modules, "woosh_msgs.msg", None)
    assert main(["driver"]) == 1
    err = capsys.readouterr().err
    assert "woosh_msgs is not generated" in err and "-m lowerbase.driver.msggen" in err
    assert "make" not in err.split()


# -- the probe: a ROS node in a subprocess that records topics and publishes on request ---------

PROBE = r'''
import json, sys, threading, time
import rospy
from roslib.message import get_message_class

def to_plain(v):
    if hasattr(v, "__slots__"):
        if hasattr(v, "secs") and hasattr(v, "nsecs"):
            return v.secs + 1e-9 * v.nsecs
        return {k: to_plain(getattr(v, k)) for k in v.__slots__}
    if isinstance(v, (list, tuple)):
        return [to_plain(x) for x in v]
    if isinstance(v, bytes):
        return list(v)
    return v

rospy.init_node("probe", disable_signals=True)
lock = threading.Lock()
seen = {}

def make_cb(topic):
    def cb(msg):
        now = time.monotonic()
        header = getattr(msg, "header", None)
        sent = header.stamp.to_sec() if header is not None else None
        with lock:
            entry = seen.setdefault(topic, {"count": 0, "first": now, "stamps": [],
                                            "sent": []})
            entry["count"] += 1
            entry["last"] = now
            entry["stamps"].append(now)
            entry["sent"].append(sent)
            entry["msg"] = msg
    return cb

subs = []
for spec in sys.argv[1:]:
    topic, type_ = spec.split("=")
    subs.append(rospy.Subscriber(topic, get_message_class(type_), make_cb(topic), queue_size=50))
pubs = {}

def publish(topic, type_, fields, rate, duration):
    cls = get_message_class(type_)
    if topic not in pubs:
        pubs[topic] = rospy.Publisher(topic, cls, queue_size=10)
        deadline = time.monotonic() + 90  # a hang guard: a busy host connects slowly
        while pubs[topic].get_num_connections() == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
    msg = cls()
    for part, values in fields.items():  # part "": fields of the message itself
        for k, v in values.items():
            setattr(getattr(msg, part) if part else msg, k, v)
    end = time.monotonic() + duration
    while time.monotonic() < end:
        pubs[topic].publish(msg)
        time.sleep(1.0 / rate)

print(json.dumps({"ready": True}), flush=True)
for line in sys.stdin:
    req = json.loads(line)
    op = req["op"]
    if op == "stats":
        since = req.get("since", 0)
        with lock:
            out = {}
            for t, e in seen.items():
                sent = [h for s, h in zip(e["stamps"], e["sent"]) if s >= since]
                # the rate by the messages' own stamps: a backlog delivered at once (a busy
                # host) does not raise it, as counting arrivals in a window does; "cycle" by
                # the median step between stamps, which messages a busy host lost (this
                # subscriber's queue overflowing) or a sender's slipped time do not lower
                timed = len(sent) >= 3 and None not in sent and sent[-1] > sent[0]
                rate = (len(sent) - 1) / (sent[-1] - sent[0]) if timed else None
                steps = sorted(b - a for a, b in zip(sent, sent[1:])) if timed else []
                cycle = steps[len(steps) // 2] if steps else None
                out[t] = {"count": e["count"], "first": e["first"], "last": e["last"],
                          "msg": to_plain(e["msg"]), "recent": len(sent), "rate": rate,
                          "cycle": cycle}
        print(json.dumps(out), flush=True)
    elif op == "types":
        print(json.dumps(dict(rospy.get_published_topics())), flush=True)
    elif op == "publish":
        threading.Thread(target=publish, daemon=True, args=(
            req["topic"], req["type"], req["fields"], req["rate"], req["duration"])).start()
        print(json.dumps({"ok": True, "t": time.monotonic()}), flush=True)
    elif op == "now":
        print(json.dumps({"t": time.monotonic()}), flush=True)
    elif op == "call":
        from roslib.message import get_service_class
        rospy.wait_for_service(req["name"], timeout=90)
        proxy = rospy.ServiceProxy(req["name"], get_service_class(req["type"]))
        print(json.dumps(to_plain(proxy(**req.get("args", {})))), flush=True)
    elif op == "quit":
        break
rospy.signal_shutdown("done")
'''


class Probe:
    """Talks to the probe subprocess: one JSON request line, one JSON reply line."""

    def __init__(self, script: Path, env: dict[str, str], topics: dict[str, str]) -> None:
        self.popen = subprocess.Popen(
            [sys.executable, str(script), *(f"{t}={ty}" for t, ty in topics.items())],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, **env},
        )
        assert self._read(30.0) == {"ready": True}

    def _read(self, timeout: float) -> Any:
        assert self.popen.stdout is not None
        ready, _, _ = select.select([self.popen.stdout], [], [], timeout)
        line = self.popen.stdout.readline() if ready else ""
        if not line:
            self.popen.kill()
            _, err = self.popen.communicate()
            raise AssertionError(f"probe gave no answer; stderr={err[-2000:]!r}")
        return json.loads(line)

    def ask(self, **request: Any) -> Any:
        assert self.popen.stdin is not None
        self.popen.stdin.write(json.dumps(request) + "\n")
        self.popen.stdin.flush()
        return self._read(10.0)

    def wait_for(self, condition: Callable[[dict[str, Any]], bool], timeout: float,
                 what: str) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        stats: dict[str, Any] = {}
        while time.monotonic() < deadline:
            stats = self.ask(op="stats")
            try:
                if condition(stats):
                    return stats
            except (KeyError, IndexError):
                pass
            time.sleep(0.05)
        summary = {t: (e["count"], e["msg"]) for t, e in stats.items() if t != "/tf"}
        raise AssertionError(f"timed out waiting for {what}; seen: {summary}")

    def close(self) -> None:
        if self.popen.poll() is None:
            try:
                self.ask(op="quit")
                self.popen.wait(timeout=10)
            except (AssertionError, BrokenPipeError, subprocess.TimeoutExpired):
                self.popen.kill()
                self.popen.wait()


@pytest.fixture(scope="module")
def rig(ros_master: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """Emulator + driver_base + probe on the module's master."""
    tmp = tmp_path_factory.mktemp("driver_node")
    bus = {"interface": "udp_multicast", "channel": TEST_GROUP, "port": free_udp_port(),
           "hop_limit": 0}
    procs: list[Proc] = []
    probe: Probe | None = None
    try:
        emulator = Proc(["emulate", *bus_cli_args(bus)], ros_master.env)
        procs.append(emulator)
        emulator.wait_for("lower computer on")
        # the node as a user starts it: no ROS_IP (it must choose loopback by itself)
        node_env = {k: v for k, v in ros_master.env.items() if k != "ROS_IP"}
        node = Proc(["driver", *bus_cli_args(bus), "__name:=driver_base"], node_env)
        procs.append(node)
        node.wait_for("link ready", timeout=BOUND)
        script = tmp / "probe.py"
        script.write_text(PROBE)
        probe = Probe(script, ros_master.env, {**PUBLISHED, **EXTRA})
        yield {"env": ros_master.env, "probe": probe, "node": node, "tmp": tmp, "bus": bus,
               "procs": procs}
    finally:
        if probe is not None:
            probe.close()
        for p in reversed(procs):
            p.stop()


def _msg(stats: dict[str, Any], topic: str) -> dict[str, Any]:
    msg: dict[str, Any] = stats[topic]["msg"]
    return msg


@pytest.mark.ros
@pytest.mark.process
def test_every_topic_is_there_with_the_vendor_type(rig: dict[str, Any]) -> None:
    probe: Probe = rig["probe"]
    probe.wait_for(lambda s: all(s.get(t, {}).get("count") for t in PUBLISHED), BOUND,
                   "a message on every topic")
    types = probe.ask(op="types")
    for topic, type_ in PUBLISHED.items():
        assert types.get(topic) == type_, topic
    assert _msg(probe.ask(op="stats"), "/driver_base/link_state")["data"] == "ready"
    # the node subscribes to the command topics with the vendor types
    import xmlrpc.client

    master = xmlrpc.client.ServerProxy(rig["env"]["ROS_MASTER_URI"])
    _, _, (_, subscribers, _) = master.getSystemState("/pytest")
    subscribed = {topic for topic, nodes in subscribers if "/driver_base" in nodes}
    assert set(SUBSCRIBED) <= subscribed
    _, _, topic_types = master.getTopicTypes("/pytest")
    assert {t: ty for t, ty in topic_types if t in SUBSCRIBED} == SUBSCRIBED


@pytest.mark.ros
@pytest.mark.process
def test_parameter_and_information_come_from_the_lower_computer(rig: dict[str, Any]) -> None:
    profile = load_profile()
    stats = rig["probe"].wait_for(
        lambda s: s["/information"]["count"] and s["/driver_base/parameter"]["count"], BOUND,
        "/information and /driver_base/parameter")
    param = _msg(stats, "/driver_base/parameter")
    c = profile.chassis
    assert param["wheelPerimeter"] == pytest.approx(c.wheel_perimeter, rel=1e-6)
    assert param["wheelDistant"] == pytest.approx(c.wheel_distant, rel=1e-6)
    assert param["pulsePerCircle"] == c.pulse_per_circle
    assert param["maxLinear"] == pytest.approx(c.max_linear, rel=1e-6)
    info = _msg(stats, "/information")
    assert info["hardwareVersion"] == profile.identity.hardware_version
    assert info["softwareVersion"] == profile.identity.software_version
    assert info["movebaseType"] == profile.identity.movebase_type
    assert info["parameter"]["ratioLeft"] == pytest.approx(c.ratio_left)


@pytest.mark.ros
@pytest.mark.process
def test_rates_follow_the_frame_cycles_and_values_make_sense(rig: dict[str, Any]) -> None:
    probe: Probe = rig["probe"]
    since = probe.ask(op="now")["t"]
    window = 2.0
    time.sleep(window)  # a measurement window, not a wait for a condition
    stats = probe.ask(op="stats", since=since)
    expected = {"/odom": 50, "/odom_raw": 50, "/imu/data_raw": 100, "/odom_twist": 50,
                "/status_code": 10, "/odometer": 10}
    for topic, hz in expected.items():  # by header stamps where the message has them
        got = stats[topic]
        if got["cycle"]:
            # the cycle between two stamps, and never more messages than the cycles: a busy
            # host can lose messages or slip the emulator's time, but not add any
            assert 0.8 / hz <= got["cycle"] <= 1.25 / hz, (topic, got["cycle"])
            assert got["rate"] <= 1.3 * hz, (topic, got["rate"])
        else:  # no stamps: counted in the window
            assert 0.6 * hz <= got["recent"] / window <= 1.3 * hz, (topic, got["recent"])
    assert 1 <= stats["/battery"]["recent"] <= 3
    imu = _msg(stats, "/imu/data_raw")
    assert imu["orientation_covariance"][0] == -1.0
    assert imu["header"]["frame_id"] == "base_link"
    assert imu["linear_acceleration"]["z"] == pytest.approx(9.81, abs=0.8)
    battery, bms = _msg(stats, "/battery"), _msg(stats, "/driver_base/bms")
    assert battery["batteryPercentage"] == 80  # the emulator's default state of charge
    assert bms["voltageTotal"] == pytest.approx(battery["batteryVoltage"], abs=0.5)
    odom = _msg(stats, "/odom")
    assert (odom["header"]["frame_id"], odom["child_frame_id"]) == ("odom", "base_link")
    assert odom["pose"]["covariance"][0] > 0 and odom["pose"]["covariance"][14] >= 1e5
    tf = _msg(stats, "/tf")["transforms"][0]
    assert (tf["header"]["frame_id"], tf["child_frame_id"]) == ("odom", "base_link")
    assert _msg(stats, "/status_code")["data"] >= 0


@pytest.mark.ros
@pytest.mark.process
def test_base_cmd_vel_drives_the_robot_and_stale_commands_stop_it(rig: dict[str, Any]) -> None:
    probe: Probe = rig["probe"]
    start = probe.ask(op="stats")
    x0, raw0 = (_msg(start, t)["pose"]["pose"]["position"]["x"] for t in ("/odom", "/odom_raw"))
    probe.ask(op="publish", topic="/base_cmd_vel", type="geometry_msgs/Twist",
              fields={"linear": {"x": 0.4}, "angular": {"z": 0.0}}, rate=20, duration=1.5)
    probe.wait_for(lambda s: _msg(s, "/odom_twist")["linear"]["x"] > 0.3, BOUND,
                   "odom_twist at the commanded speed")
    moved = probe.wait_for(
        lambda s: _msg(s, "/odom")["pose"]["pose"]["position"]["x"] > x0 + 0.15, BOUND,
        "/odom moving forward")
    assert _msg(moved, "/odom_raw")["pose"]["pose"]["position"]["x"] > raw0 + 0.1
    tf = _msg(moved, "/tf")["transforms"][0]["transform"]["translation"]
    assert tf["x"] > x0 + 0.1
    # the publisher stops after 1.5 s: 0.5 s later the command is stale and the robot stops
    stopped = probe.wait_for(
        lambda s: abs(_msg(s, "/odom_twist")["linear"]["x"]) < 0.005
        and time.monotonic() > s["/odom_twist"]["first"], BOUND, "odom_twist back to zero")
    assert abs(_msg(stopped, "/odom")["twist"]["twist"]["linear"]["x"]) < 0.05


@pytest.mark.ros
@pytest.mark.process
def test_rosbag_record_reads_back(rig: dict[str, Any]) -> None:
    import rosbag

    bag_path = rig["tmp"] / "run.bag"
    topics = [t for t in PUBLISHED if t != "/driver_base/link_state"]
    rec = subprocess.run(
        ["rosbag", "record", "--duration=2", "-O", str(bag_path), *topics],
        env={**os.environ, **rig["env"]}, capture_output=True, text=True, timeout=BOUND,
        cwd=rig["tmp"],
    )
    assert rec.returncode == 0, rec.stderr
    with rosbag.Bag(str(bag_path)) as bag:
        info = bag.get_type_and_topic_info().topics
        for topic in ("/odom", "/odom_raw", "/imu/data_raw", "/odom_twist", "/status_code",
                      "/driver_base/parameter", "/information", "/tf"):
            assert info[topic].msg_type == PUBLISHED[topic], topic
            assert info[topic].message_count >= 1, topic
        assert info["/odom"].message_count >= 40  # 50 Hz for about 2 s
        _, battery, _ = next(bag.read_messages(topics=["/battery", "/driver_base/parameter"]))
        assert battery._type in ("woosh_msgs/Battery", "woosh_msgs/Parameter")


@pytest.mark.ros
@pytest.mark.process
def test_rostopic_echo_battery_with_ros_package_path_only(rig: dict[str, Any]) -> None:
    env = {**os.environ, **rig["env"]}
    env.pop("PYTHONPATH")  # the system rostopic finds woosh_msgs through ROS_PACKAGE_PATH
    out = subprocess.run(["rostopic", "echo", "-n1", "/battery"], env=env, capture_output=True,
                         text=True, timeout=BOUND)
    assert out.returncode == 0, out.stderr
    assert "batteryPercentage: 80" in out.stdout
    out = subprocess.run(["rostopic", "echo", "-n1", "/driver_base/parameter"], env=env,
                         capture_output=True, text=True, timeout=BOUND)
    assert "pulsePerCircle: 10000" in out.stdout  # latched: a late subscriber gets it


@pytest.mark.ros
@pytest.mark.process
def test_roslaunch_starts_the_node_with_the_parameter_file(rig: dict[str, Any]) -> None:
    """The launch file in a namespace of its own, against a second emulator."""
    import yaml

    tmp: Path = rig["tmp"]
    bus = {**rig["bus"], "port": free_udp_port()}
    emulator = Proc(["emulate", *bus_cli_args(bus)], rig["env"])
    rig["procs"].append(emulator)
    emulator.wait_for("lower computer on")
    params = yaml.safe_load(CONFIG.read_text())
    params["topics"] = {k: v.lstrip("/") for k, v in params["topics"].items()}  # in /launched
    params["publish_tf"] = False
    config = tmp / "launched.yaml"
    config.write_text(yaml.safe_dump(params))
    bus_args = " ".join(bus_cli_args(bus))
    env = {**os.environ, **rig["env"], "ROS_NAMESPACE": "/launched"}
    # what roslaunch will run: the package's script with the given interpreter and bus
    args = subprocess.run(
        ["roslaunch", "--args", "driver_base", str(LAUNCH), f"bus_args:={bus_args}",
         f"python:={sys.executable}"], env=env, capture_output=True, text=True, timeout=BOUND)
    assert args.returncode == 0, args.stderr
    assert args.stdout.split()[:2] == [sys.executable, str(DRIVER_DIR / "scripts" /
                                                           "driver_base")]
    launch = subprocess.Popen(
        ["roslaunch", str(LAUNCH), f"bus_args:={bus_args}", f"python:={sys.executable}",
         f"config:={config}", "publish_tf:=false"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp)
    try:
        stats = rig["probe"].wait_for(
            lambda s: _msg(s, "/launched/driver_base/link_state")["data"] == "ready"
            and s["/launched/odom"]["count"] > 5, BOUND, "the launched node ready")
        assert _msg(stats, "/launched/odom")["child_frame_id"] == "base_link"
    finally:
        launch.send_signal(2)
        try:
            launch.wait(timeout=BOUND)
        except subprocess.TimeoutExpired:
            launch.kill()
            launch.wait()


@pytest.mark.ros
@pytest.mark.process
def test_replay_feeds_a_recorded_run_through_the_driver(rig: dict[str, Any]) -> None:
    import can

    from lowerbase.simloop.loop import SimLoop

    path = rig["tmp"] / "run.log"
    with can.Logger(str(path)) as logger:

        def tap(t: float, side: str, frame_id: int, data: bytes) -> None:
            logger.on_message_received(can.Message(timestamp=1000.0 + t, arbitration_id=frame_id,
                                                   data=data, is_extended_id=False,
                                                   is_rx=side == "lower"))

        loop = SimLoop(tap=tap)
        loop.run(1.0)
        loop.drive(0.5, 0.0, 2.0)
    names = ["/odom", "/odom_raw", "/imu/data_raw", "/battery", "/driver_base/bms",
             "/driver_base/parameter", "/information", "/base_cmd_vel", "/smooth_cmd_vel"]
    remaps = [f"{n}:=/replay{n}" for n in names]
    replay = Proc(["driver", "--replay", str(path), "__name:=replayer", "__ns:=/replay",
                   "_publish_tf:=false", *remaps], rig["env"])
    rig["procs"].append(replay)
    replay.wait_for("link ready", timeout=BOUND)
    stats = rig["probe"].wait_for(
        lambda s: _msg(s, "/replay/odom_twist")["linear"]["x"] > 0.4, 10.0,
        "the replayed run moving")
    assert stats["/replay/odom"]["count"] > 10
    code, err = replay.wait(timeout=BOUND)
    assert code == 0, err
    assert "lowerbase driver: replay finished" in err


@pytest.mark.ros
@pytest.mark.process
def test_services_operate_the_chassis(rig: dict[str, Any]) -> None:
    """std_srvs services called from another node: e-stop, release + enable, odometer reset,
    fault clear (of a rejected frame sent on the bus) and reboot, checked on the topics."""
    import xmlrpc.client

    from lowerbase.protocol.status_codes import StatusBit
    from lowerbase.transport import open_bus

    probe: Probe = rig["probe"]
    master = xmlrpc.client.ServerProxy(rig["env"]["ROS_MASTER_URI"])
    _, _, (_, _, services) = master.getSystemState("/pytest")
    offered = {name for name, nodes in services if "/driver_base" in nodes}
    assert {"/driver_base/enable", "/driver_base/standby", "/driver_base/estop",
            "/driver_base/fault_clear", "/driver_base/odometer_reset",
            "/driver_base/reboot"} <= offered

    def call(name: str, **args: Any) -> dict[str, Any]:
        type_ = "std_srvs/SetBool" if name == "estop" else "std_srvs/Trigger"
        reply: dict[str, Any] = probe.ask(op="call", name=f"/driver_base/{name}", type=type_,
                                          args=args)
        assert reply["success"], reply
        return reply

    def status(bit: StatusBit, on: bool, what: str) -> None:
        probe.wait_for(lambda s: bool(_msg(s, "/status_code")["data"] & bit) == on, BOUND, what)

    def drive() -> None:
        probe.ask(op="publish", topic="/base_cmd_vel", type="geometry_msgs/Twist",
                  fields={"linear": {"x": 0.3}, "angular": {"z": 0.0}}, rate=20, duration=1.0)

    assert call("estop", data=True)["message"] == "EStopSet sent"
    status(StatusBit.ESTOP_COMMAND, True, "the e-stop bit set")
    call("estop", data=False)
    status(StatusBit.ESTOP_COMMAND, False, "the e-stop bit released")
    call("enable")  # released into standby: enable again, no driver restart
    drive()
    probe.wait_for(lambda s: _msg(s, "/odometer")["data"] > 0.1, BOUND, "odometer counting")
    call("odometer_reset")
    probe.wait_for(lambda s: _msg(s, "/odometer")["data"] < 0.05, BOUND, "odometer reset")

    bus = open_bus(rig["bus"])  # a MotionCommand too short to decode: latched COMMAND_REJECTED
    try:
        import can

        from lowerbase.protocol.codec import default_codec

        frame_id = default_codec().message("MotionCommand").frame_id
        bus.send(can.Message(arbitration_id=frame_id, data=b"\x01", is_extended_id=False))
    finally:
        bus.shutdown()
    status(StatusBit.COMMAND_REJECTED, True, "a rejected command latched")
    call("fault_clear")
    status(StatusBit.COMMAND_REJECTED, False, "the latched fault cleared")

    call("reboot")
    rig["node"].wait_for("link configuring", timeout=BOUND)
    rig["node"].wait_for("link ready", timeout=BOUND)
    drive()  # re-enabled by the driver after the reboot
    probe.wait_for(lambda s: _msg(s, "/odom_twist")["linear"]["x"] > 0.2, BOUND,
                   "driving after the reboot")


@pytest.mark.ros
@pytest.mark.process
def test_the_vendors_shelf_led_topic_reaches_the_bus(rig: dict[str, Any]) -> None:
    """The vendor's robot publishes the shelf strip on /kShelfLedColorPubName: heard by default,
    sent as a LedCommand for strip 1 (read off the bus by this test)."""
    from lowerbase.protocol.codec import default_codec
    from lowerbase.transport import open_bus

    led = default_codec().message("LedCommand")
    bus = open_bus(rig["bus"])
    try:
        rig["probe"].ask(op="publish", topic="/kShelfLedColorPubName", type="woosh_msgs/LED",
                         fields={"": {"submodule": 2, "color": 0x123456}}, rate=10, duration=1.0)
        deadline = time.monotonic() + 5.0
        seen: dict[str, Any] = {}
        while time.monotonic() < deadline and not seen:
            msg = bus.recv(0.1)
            if msg is not None and msg.arbitration_id == led.frame_id:
                seen = dict(led.decode(bytes(msg.data)))
    finally:
        bus.shutdown()
    assert seen, "no LedCommand on the bus"
    assert (int(seen["Strip"]), int(seen["Submodule"]), int(seen["Color"])) == (1, 2, 0x123456)


def _listening_addresses(pid: int) -> set[str]:
    """Local addresses of the TCP sockets process ``pid`` listens on (from /proc)."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        with contextlib.suppress(OSError):
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    found = set()
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/{pid}/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] == "0A" and fields[9] in inodes:  # 0A: LISTEN
                found.add(fields[1].rsplit(":", 1)[0])
    return found


@pytest.mark.ros
@pytest.mark.process
def test_the_node_listens_on_loopback_when_the_master_is_local(rig: dict[str, Any]) -> None:
    """Started without ROS_IP/ROS_HOSTNAME against a master on 127.0.0.1 (as by default)."""
    import xmlrpc.client

    if os.environ.get("ROS_IP") or os.environ.get("ROS_HOSTNAME"):
        pytest.skip("ROS_IP/ROS_HOSTNAME set in the test environment")
    node: Proc = rig["node"]
    assert any("listening on loopback only" in line for line in node.lines)
    addresses = _listening_addresses(node.popen.pid)
    assert len(addresses) >= 1  # XML-RPC and TCPROS servers
    assert addresses == {"0100007F"}, addresses  # 127.0.0.1, nothing on 0.0.0.0
    master = xmlrpc.client.ServerProxy(rig["env"]["ROS_MASTER_URI"])
    _, _, uri = master.lookupNode("/pytest", "/driver_base")
    assert uri.startswith("http://127.0.0.1:")


def test_odom_read_without_its_message_is_what_the_message_gives(woosh_msgs: Any) -> None:
    # the lockstep faces take /odom's pose (and TF) without the Odometry message being built:
    # the same floats, bit for bit, as reading the message and its transform
    from lowerbase.driver import ros_io

    rng = random.Random(7)
    poses = [(rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-math.pi, math.pi))
             for _ in range(2000)] + [(0.0, 0.0, math.pi), (1.0, -1.0, -math.pi), (0, 0, 0),
                                      (0.0, -0.0, -0.0), (2.0, 3.0, 1e-300), (0.0, 0.0, 4.0)]
    import genpy

    stamp = genpy.Time(3, 5)
    for pose in poses:
        msg = ros_io.odometry_msg(stamp, "odom", "base_link", pose, (0.0, 0.0), [0.0] * 9,
                                  [0.0] * 4, 1e6)
        assert repr(ros_io.odom_pose_of(pose)) == repr(ros_io.odom_pose(msg))  # -0.0 too
        a, b = ros_io.odom_transform(stamp, "odom", "base_link", pose), \
            ros_io.transform_from_odometry(msg)
        assert (a.header.frame_id, a.child_frame_id) == (b.header.frame_id, b.child_frame_id)
        ta, tb = a.transform, b.transform
        assert (ta.translation.x, ta.translation.y, ta.translation.z) == \
            (tb.translation.x, tb.translation.y, tb.translation.z)
        assert (ta.rotation.x, ta.rotation.y, ta.rotation.z, ta.rotation.w) == \
            (tb.rotation.x, tb.rotation.y, tb.rotation.z, tb.rotation.w)
        wire_a, wire_b = io.BytesIO(), io.BytesIO()
        a.serialize(wire_a)
        b.serialize(wire_b)
        assert wire_a.getvalue() == wire_b.getvalue()  # /tf's bytes, seq and z included
