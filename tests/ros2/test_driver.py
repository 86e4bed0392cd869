"""``lowerbase driver --ros2`` against the emulated lower computer, with rclpy clients in
processes of their own (tests/ros2/ros2_driver_probe.py).

One emulator and one driver serve the module. Every check waits on a condition with a
generous deadline (a cold numba cache compiles the EKF's kernels at the driver's start; a
loaded 2-core host delays everything), never on a sleep.
"""

from __future__ import annotations

import contextlib
import os
import queue
import subprocess
import sys
import threading
from collections.abc import Iterator

import pytest

from tests.conftest import ROOT, TEST_GROUP, Proc, bus_cli_args, free_udp_port
from tests.ros2.conftest import HERE, Ros2, ros2_or_skip

START_TIMEOUT = 300.0  # a cold start compiles numba kernels (minutes on a busy host)


class Ros2Proc(Proc):
    """:class:`Proc` with a command and an environment of its own (the ROS 2 venv's)."""

    def __init__(self, cmd: list[str], env: dict[str, str]) -> None:
        self.popen = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True, cwd=ROOT, env=env)
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()


def udp_bound_beyond_loopback(pid: int) -> list[str]:
    """The local addresses of ``pid``'s UDP sockets (IPv4 and IPv6) that are neither
    loopback nor a multicast group (the bus's own is one)."""
    import ipaddress

    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        with contextlib.suppress(OSError):
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    bad = []
    for table in ("udp", "udp6"):
        with open(f"/proc/{pid}/net/{table}") as f:
            rows = [line.split() for line in f.readlines()[1:]]
        for row in rows:
            if row[9] not in inodes:
                continue
            hex_addr, hex_port = row[1].split(":")
            raw = bytes.fromhex(hex_addr)
            if len(raw) == 4:
                address = ipaddress.ip_address(raw[::-1])
            else:  # four little-endian 32-bit words
                address = ipaddress.ip_address(b"".join(raw[i:i + 4][::-1]
                                                        for i in range(0, 16, 4)))
            if not (address.is_loopback or address.is_multicast):
                bad.append(f"{address}:{int(hex_port, 16)}")
    return bad


@contextlib.contextmanager
def robot_on_ros2(ros2: Ros2, args: list[str], *named: str,
                  env: dict[str, str] | None = None) -> Iterator[None]:
    """``lowerbase robot --ros2 ARGS`` of the ROS 2 venv for the block: its start line names
    /lowerbase_robot and each of ``named``, nothing of it is bound beyond loopback, and at the
    end Ctrl-C stops it with its stop line and no traceback."""
    proc = Ros2Proc([str(ros2.python), "-m", "lowerbase", "robot", "--ros2", *args],
                    ros2.env if env is None else env)
    try:
        line = proc.wait_for("on ROS 2", timeout=START_TIMEOUT)
        assert "/lowerbase_robot" in line and all(n in line for n in named), line
        assert udp_bound_beyond_loopback(proc.popen.pid) == []
        yield
        code, err = proc.stop(timeout=60)
        assert code == 0, err
        assert "lowerbase robot: stopped at" in err, err
        assert "Traceback" not in err, err
    finally:
        proc.stop(timeout=60)


@pytest.fixture(scope="module")
def driver() -> Iterator[Ros2]:
    """An emulator and ``lowerbase driver --ros2`` on a udp_multicast port of their own."""
    ros2 = ros2_or_skip()
    bus = {"interface": "udp_multicast", "channel": TEST_GROUP, "port": free_udp_port(),
           "hop_limit": 0}
    emulator = Ros2Proc([sys.executable, "-m", "lowerbase", "emulate", *bus_cli_args(bus)],
                        dict(os.environ))
    procs = [emulator]
    try:
        emulator.wait_for("lower computer on", timeout=60)
        node = Ros2Proc([str(ros2.python), "-m", "lowerbase", "driver", "--ros2",
                         *bus_cli_args(bus)], ros2.env)
        procs.append(node)
        line = node.wait_for("on ROS 2", timeout=START_TIMEOUT)
        assert "/driver_base" in line and "discovery loopback only" in line, line
        assert udp_bound_beyond_loopback(node.popen.pid) == []
        yield ros2
        code, err = node.stop(timeout=30)
        assert code == 0, err
        assert "lowerbase driver: stopped;" in err, err
    finally:
        for p in reversed(procs):
            p.stop(timeout=30)


def test_odom_at_50_hz(driver: Ros2) -> None:
    got = driver.run_json("ros2_driver_probe.py", "odom", "100", timeout=200)
    assert got["frame_id"] == "odom" and got["child_frame_id"] == "base_link"
    assert got["backwards"] == 0
    assert 45.0 <= got["rate"] <= 55.0, got  # WheelFeedback every 20 ms, /odom on each


def test_late_subscriber_gets_the_latched_topics(driver: Ros2) -> None:
    got = driver.run_json("ros2_driver_probe.py", "latched", timeout=200)
    assert got["link_state"] in ("configuring", "ready")
    assert got["wheelPerimeter"] > 0 and got["pulsePerCircle"] > 0
    assert got["hardwareVersion"]


def test_trigger_service(driver: Ros2) -> None:
    got = driver.run_json("ros2_driver_probe.py", "service", "/driver_base/odometer_reset",
                          timeout=200)
    assert got == {"success": True, "message": "OdometerReset sent"}


def test_twist_moves_the_robot(driver: Ros2) -> None:
    got = driver.run_json("ros2_driver_probe.py", "drive", timeout=200)
    assert got["moved"] >= 0.2
    assert got["speed"] == pytest.approx(0.3, abs=0.1)


def test_parameters_are_ros2_parameters(driver: Ros2) -> None:
    got = driver.run_json("ros2_driver_probe.py", "params", timeout=200)
    assert got == {"topics.odom": "/odom", "command_rate": 50.0, "publish_tf": True}


def test_log_lines_go_to_rosout(driver: Ros2) -> None:
    """lowerbase's log records are the node's: driver_base's warning about twists with NaN
    reaches an rclpy subscriber of /rosout (rcl_interfaces/msg/Log), at WARN."""
    got = driver.run_json("ros2_driver_probe.py", "rosout", timeout=300)
    assert got["level"] == 30 and got["name"] == "driver_base", got  # Log.WARN
    assert "ignored 1 twist(s) with NaN or infinity" in got["msg"], got


def test_tf_and_imu(driver: Ros2) -> None:
    assert driver.run_json("ros2_driver_probe.py", "tf", timeout=200) == \
        {"frame_id": "odom", "child_frame_id": "base_link"}
    imu = driver.run_json("ros2_driver_probe.py", "imu", timeout=200)
    assert imu["frame_id"] == "base_link" and imu["orientation_covariance0"] == -1.0
    assert imu["accel_z"] == pytest.approx(9.8, abs=0.5)


def test_imu_and_battery_at_their_rates(driver: Ros2) -> None:
    """/imu/data_raw at 100 Hz and /battery at 1 Hz (docs/driver.md's table), by their
    stamps over ~5 s; the battery as the emulator's pack reports it. This is real time: when
    a busy host made the emulator's time slip (driver_base then says so on /rosout), fewer
    samples came per wall second, never more."""
    got = driver.run_json("ros2_driver_probe.py", "rates", timeout=300)
    if got["slips"]:
        assert got["imu"] < 105.0 and got["battery"] < 1.15, got
    else:
        assert got["imu"] == pytest.approx(100.0, rel=0.05), got
        assert got["battery"] == pytest.approx(1.0, rel=0.15), got
    assert 0 < got["percentage"] <= 100 and 40.0 < got["voltage"] < 60.0, got


def test_late_subscriber_gets_tf_static(ros2: Ros2) -> None:
    pub = Ros2Proc([str(ros2.python), str(HERE / "ros2_driver_probe.py"), "static_pub"],
                   ros2.env)
    try:
        pub.wait_for("published", timeout=120)
        got = ros2.run_json("ros2_driver_probe.py", "static_sub", timeout=200)
    finally:
        pub.stop(timeout=30)
    assert got == {"laser": 0.2, "camera": 0.3}


def test_use_sim_time_follows_clock(ros2: Ros2) -> None:
    """``_use_sim_time:=true``: the driver waits for /clock, then stamps /odom on its time
    (here 1000 s and on, at the wall's pace) and still publishes it at 50 Hz of it."""
    bus = {"interface": "udp_multicast", "channel": TEST_GROUP, "port": free_udp_port(),
           "hop_limit": 0}
    procs = [Ros2Proc([sys.executable, "-m", "lowerbase", "emulate", *bus_cli_args(bus)],
                      dict(os.environ))]
    try:
        procs[0].wait_for("lower computer on", timeout=60)
        node = Ros2Proc([str(ros2.python), "-m", "lowerbase", "driver", "--ros2",
                         *bus_cli_args(bus), "_use_sim_time:=true"], ros2.env)
        procs.append(node)
        node.wait_for("waiting for /clock", timeout=START_TIMEOUT)
        clock = Ros2Proc([str(ros2.python), str(HERE / "ros2_driver_probe.py"), "clock_pub",
                          "1000"], ros2.env)
        procs.append(clock)
        node.wait_for("on ROS 2", timeout=START_TIMEOUT)
        got = ros2.run_json("ros2_driver_probe.py", "odom", "100", timeout=200)
    finally:
        for p in reversed(procs):
            p.stop(timeout=30)
    assert 1000.0 <= got["first"] < 1000.0 + START_TIMEOUT + 200.0, got
    assert got["backwards"] == 0
    assert 40.0 <= got["rate"] <= 60.0, got
