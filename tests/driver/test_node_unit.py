"""DriverNode without a master: its ROS callbacks on a simulated clock (rospy and the generated
woosh_msgs are imported, nothing is advertised)."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from lowerbase.clock import SimClock
from lowerbase.driver.settings import load_settings


class RecordingLink:
    description = "a list"

    def __init__(self) -> None:
        self.sent: list[tuple[int, bytes]] = []

    def send(self, frame_id: int, data: bytes) -> None:
        self.sent.append((frame_id, data))

    def close(self) -> None:
        pass


def test_nan_twists_are_refused_counted_and_logged_once_per_period(
        woosh_msgs: Any, caplog: pytest.LogCaptureFixture) -> None:
    from geometry_msgs.msg import Twist

    from lowerbase.driver.node import DriverNode

    clock, link = SimClock(), RecordingLink()
    settings, config = load_settings({})  # malformed_log_period 5 s
    node = DriverNode(settings, config, link, clock=clock)
    bad = Twist()
    bad.linear.x = float("nan")
    with caplog.at_level(logging.WARNING):
        for _ in range(160):  # 10 s at 16 Hz
            node._on_twist(bad, False)
            clock.advance(0.0625)
    lines = [r.getMessage() for r in caplog.records if "NaN" in r.getMessage()]
    assert len(lines) == 2, lines  # t = 0 and t = 5 s, not 160
    assert lines[0].startswith("ignored 1 twist(s)") and lines[1].startswith("ignored 80 ")
    assert node.core.stats["twist_rejected"] == 160
    assert link.sent == [] and not node.core.commanding
    good = Twist()
    good.linear.x = 0.2
    node._on_twist(good, False)
    assert node.core.commanding and len(link.sent) == 1


SCRIPT = Path(__file__).resolve().parents[2] / "lowerbase" / "driver" / "scripts" / "driver_base"


def _one_line_hint(result: subprocess.CompletedProcess[str], missing: str) -> None:
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith("driver_base: ") and f"cannot import {missing}" in \
        result.stderr and "python:=" in result.stderr


def test_launch_script_says_which_interpreter_to_pass_when_a_dependency_is_missing() -> None:
    code = ("import runpy, sys; sys.modules['cantools'] = None; sys.argv = [sys.argv[1]]; "
            "runpy.run_path(sys.argv[0], run_name='__main__')")
    result = subprocess.run([sys.executable, "-c", code, str(SCRIPT)], capture_output=True,
                            text=True, timeout=60)
    _one_line_hint(result, "cantools")


@pytest.mark.skipif(not Path("/usr/bin/python3").exists(), reason="no /usr/bin/python3")
def test_launch_script_under_the_system_python_without_the_dependencies() -> None:
    """What roslaunch does without python:= on Debian: /usr/bin/python3 runs the script."""
    probe = subprocess.run(["/usr/bin/python3", "-c", "import numpy, filterpy"],
                           capture_output=True, timeout=60)
    if probe.returncode == 0:
        pytest.skip("/usr/bin/python3 has lowerbase's dependencies here")
    result = subprocess.run(["/usr/bin/python3", str(SCRIPT), "__name:=driver_base"],
                            capture_output=True, text=True, timeout=60,
                            env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    assert result.returncode == 1
    assert "Traceback" not in result.stderr and "python:=" in result.stderr


@pytest.mark.parametrize(("environ", "uri", "args", "expected"), [
    ({}, "http://localhost:11311", [], "127.0.0.1"),
    ({}, "http://127.0.0.1:41234/", [], "127.0.0.1"),
    ({}, "http://[::1]:11311", [], "::1"),
    ({"ROS_IP": ""}, "http://localhost:11311", [], "127.0.0.1"),  # empty: unset
    ({"ROS_IP": "192.168.1.5"}, "http://localhost:11311", [], None),  # the user's choice
    ({"ROS_HOSTNAME": "robot"}, "http://localhost:11311", [], None),
    ({}, "http://localhost:11311", ["__ip:=10.0.0.2"], None),
    ({}, "http://robot-master:11311", [], None),  # a remote master: rospy's default
])
def test_loopback_address(environ: dict[str, str], uri: str, args: list[str],
                          expected: str | None) -> None:
    from lowerbase.ros1.loopback import loopback_address

    hosts = {"robot-master": ["192.168.1.7"]}
    assert loopback_address(environ, uri, args, resolve=hosts.__getitem__) == expected


@pytest.mark.parametrize(("addresses", "expected"), [
    (["127.0.0.1"], "127.0.0.1"),  # roscore on a machine "vm" listed as 127.0.0.1 in /etc/hosts
    (["127.0.1.1"], "127.0.0.1"),  # Debian's own-hostname line
    (["::1"], "::1"),
    (["::1", "127.0.0.1"], "127.0.0.1"),
    (["127.0.0.1", "10.0.0.5"], None),  # also a real interface: reachable from outside
    (["fe80::1%eth0"], None),
    ([], None),  # does not resolve: rospy's default
])
def test_a_master_hostname_resolving_to_loopback_only_keeps_the_node_on_loopback(
        addresses: list[str], expected: str | None) -> None:
    from lowerbase.ros1.loopback import loopback_address

    asked: list[str] = []

    def resolve(host: str) -> list[str]:
        asked.append(host)
        return addresses

    assert loopback_address({}, "http://vm:11397/", [], resolve=resolve) == expected
    assert asked == ["vm"]


def test_the_real_resolver_on_this_hosts_own_name() -> None:
    import socket

    from lowerbase.ros1.loopback import loopback_address, resolve_host

    own = socket.gethostname()
    addresses = resolve_host(own)
    if not addresses or not all(a.startswith("127.") or a == "::1" for a in addresses):
        pytest.skip(f"{own} does not resolve to loopback only here ({addresses})")
    assert loopback_address({}, f"http://{own}:11397/") in ("127.0.0.1", "::1")
    assert resolve_host("name.invalid") == []  # RFC 2606: never resolves


def test_odom_tf_is_not_sent_twice_with_one_stamp(woosh_msgs: Any) -> None:
    """Under /use_sim_time two odometry samples can fall on one /clock tick; tf2 drops a
    transform whose stamp it has (TF_REPEATED_DATA in every listener's log), so the node sends
    each stamp once."""
    import rospy

    from lowerbase.driver.node import DriverNode

    class Broadcaster:
        def __init__(self) -> None:
            self.stamps: list[Any] = []

        def sendTransform(self, t: Any) -> None:
            self.stamps.append(t.header.stamp)

    settings, config = load_settings({})
    node = DriverNode(settings, config, RecordingLink(), clock=SimClock())
    node._tf = tf = Broadcaster()
    now = [rospy.Time(10, 0)]
    node.rospy = type("R", (), {"Time": type("T", (), {"now": staticmethod(lambda: now[0])})})
    node._publish_odometry()
    node._publish_odometry()  # the same /clock tick
    now[0] = rospy.Time(10, 20_000_000)
    node._publish_odometry()
    assert tf.stamps == [rospy.Time(10, 0), rospy.Time(10, 20_000_000)]
