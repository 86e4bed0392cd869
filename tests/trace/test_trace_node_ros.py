"""`lowerbase trace`, black-box, on the whole chain: a real rosmaster, `lowerbase emulate --map
warehouse --truth-udp` with a crate on the route, `lowerbase driver`, `lowerbase world
--ground-truth` (amcl once jumped during the detour in this corridor: docs/trace.md) and
`lowerbase trace --blocked-timeout 3`, each a process of its own; examples/business_node.py
drives it with the protobuf messages only. rosbag records the seed's topics and the bag is read
back with rosbag's own decoder (the message definition in the bag, not ours)."""

from __future__ import annotations

import itertools
import math
import os
import shutil
import signal
import subprocess
import sys
import time
import xmlrpc.client
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from lowerbase.trace import messages as m
from lowerbase.trace.modules import AVOID_STATUS, POSE, ROUTE, SPEED, STATUS, TOPICS
from tests.conftest import ROOT, Proc
from tests.driver.conftest import require_ros
from tests.ros_chain import ros_chain, write_crate
from tests.trace.test_ros_msgs import PROTOBUF_MD5
from tests.trace.trace_ros import trace_build, trace_master  # noqa: F401

BUSINESS = ROOT / "examples" / "business_node.py"
CRATE = (8.6, 1.2)
PLACE = ["--map", "warehouse", "--initial-pose", "6.0,1.2,0.0"]


def _subscribed(uri: str, topic: str, prefix: str) -> bool:
    _, _, (_, subs, _) = xmlrpc.client.ServerProxy(uri).getSystemState("/pytest")
    return any(t == topic and any(n.startswith(prefix) for n in nodes) for t, nodes in subs)


class Bag:
    """``rosbag record`` of the seed's topics until :meth:`read`."""

    def __init__(self, path: Path, master: Any) -> None:
        self.path = path
        self.proc = subprocess.Popen(
            ["rosbag", "record", "-O", str(path), "__name:=traceros_bag",
             *("/" + t for t in TOPICS)], env={**os.environ, **master.env},
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        end = time.monotonic() + 30.0
        while not all(_subscribed(master.uri, "/" + t, "/traceros_bag") for t in TOPICS):
            assert time.monotonic() < end and self.proc.poll() is None, "rosbag did not start"
            time.sleep(0.05)

    def kill(self) -> None:
        """Stop the recorder without reading (a test failed before :meth:`read`)."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(timeout=30)

    def read(self) -> list[tuple[str, float, Any, str, str]]:
        """(topic, receipt time, the decoded protobuf, datatype, md5) of every message."""
        import rosbag

        # rosbag's script forwards Ctrl-C to its `record` child but does not wait for it:
        # interrupt the whole group, then wait for the bag to be closed (renamed from .active)
        os.killpg(self.proc.pid, signal.SIGINT)
        self.proc.wait(timeout=30)
        active = self.path.with_name(self.path.name + ".active")
        end = time.monotonic() + 30.0
        while not self.path.exists() or active.exists():
            assert time.monotonic() < end, f"rosbag did not close {self.path}"
            time.sleep(0.05)
        out = []
        with rosbag.Bag(str(self.path)) as bag:
            types = {c.topic: (c.datatype, c.md5sum) for c in bag._get_connections()}
            for topic, msg, t in bag.read_messages():
                name = topic.lstrip("/")
                out.append((name, t.to_sec(), m.decode(msg.type, bytes(msg.data),
                                                       m.TYPES[msg.type]), *types[topic]))
        return out


def business(master: Any, *args: str, timeout: float = 150.0) -> list[str]:
    """Run the example to its end; its report lines (asserting exit code 0)."""
    try:
        done = subprocess.run([sys.executable, str(BUSINESS), *args], env={**os.environ,
                              **master.env}, capture_output=True, text=True, timeout=timeout,
                              cwd=ROOT)
    except subprocess.TimeoutExpired as exc:  # what it saw until then, not only "timed out"
        raise AssertionError(f"the business node did not end in {timeout:g} s: "
                             f"{exc.stdout!r} {exc.stderr!r}") from None
    assert done.returncode == 0, (done.stdout, done.stderr)
    return [line.split(" ", 1)[1] for line in done.stdout.splitlines()
            if line.startswith("business: msg_")]


def _changes(pairs: list[tuple[str, str]]) -> dict[str, list[str]]:
    """Each status topic's statuses with repeats collapsed (RUNNING, BLOCKED, RUNNING, ...)."""
    return {topic: [s for s, _ in itertools.groupby(s for t, s in pairs if t == topic)]
            for topic in (STATUS, AVOID_STATUS)}


@pytest.fixture(scope="module")
def chain(trace_master: Any, tmp_path_factory: pytest.TempPathFactory  # noqa: F811
          ) -> Iterator[dict[str, Any]]:
    require_ros(("rospy", "tf2_ros", "rosbag"))
    if shutil.which("rosbag") is None:
        pytest.skip("rosbag is not installed")
    tmp = tmp_path_factory.mktemp("traceros_chain")
    place = [*PLACE, "--obstacles", str(write_crate(tmp / "crate.toml", CRATE))]
    with ros_chain(trace_master.env, place, "239.74.163.97", timeout=60.0) as procs:
        trace = procs.start(["trace", "--map", "warehouse", "--blocked-timeout", "3",
                             "--status-period", "1"])
        line = trace.wait_for("lowerbase trace:", timeout=60.0)
        assert line.startswith(f"lowerbase trace: /trace_navigate on ROS master {trace_master.uri}")
        yield {"master": trace_master, "trace": trace, "tmp": tmp}


@pytest.mark.ros
@pytest.mark.process
def test_the_ros_tools_see_the_seeds_topics(chain: dict[str, Any]) -> None:
    env = {**os.environ, **chain["master"].env}
    env.pop("PYTHONPATH")  # the system rostopic finds lowerbase_msgs by ROS_PACKAGE_PATH alone
    for topic in TOPICS:
        out = subprocess.run(["rostopic", "type", "/" + topic], env=env, capture_output=True,
                             text=True, timeout=60)
        assert out.stdout.strip() == "lowerbase_msgs/Protobuf", (topic, out.stderr)
    out = subprocess.run(["rostopic", "echo", "-n", "1", "/" + POSE], env=env,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and 'type: "RobotPose2D"' in out.stdout, out.stderr


@pytest.mark.ros
@pytest.mark.process
def test_the_business_node_runs_the_seeds_diagram(chain: dict[str, Any]) -> None:
    bag = Bag(chain["tmp"] / "diagram.bag", chain["master"])
    lines = business(chain["master"], "--route", "6.0,1.2:7.0,1.2:10.6,1.2")
    records = bag.read()
    # what the business node saw: 1-2 RUNNING, 3-4 BLOCKED, 5-7 detour FINISHED, 8-10 FINISHED
    seen = [(t, s) for t, s, _ in (line.split(" ", 2) for line in lines)]
    blocked = seen.index((STATUS, "BLOCKED"))
    assert seen[0] == (STATUS, "RUNNING") and (STATUS, "RUNNING") in seen[1:blocked]
    avoided = seen.index((AVOID_STATUS, "FINISHED"))
    assert seen[blocked + 1:avoided] == [(AVOID_STATUS, "RUNNING")] * (avoided - blocked - 1)
    assert seen[avoided + 1] == (STATUS, "RUNNING") and seen[-1] == (STATUS, "FINISHED")
    # the same in the bag, decoded from the wire
    assert {(topic, kind, md5) for topic, _, _, kind, md5 in records} >= {
        (t, "lowerbase_msgs/Protobuf", PROTOBUF_MD5) for t in (ROUTE, STATUS, AVOID_STATUS,
                                                              SPEED, POSE)}
    statuses = [(t, m.STATUS_NAMES[msg.status]) for t, _, msg, _, _ in records
                if t in (STATUS, AVOID_STATUS)]
    # per topic, as each status changed: the bag and the business node are two subscribers
    # on connections of their own, so their order across the two topics may differ, and a
    # loaded host may drop one of a run of periodic RUNNING reports for one of them (rospy's
    # per-connection queue), never a change
    assert _changes(statuses) == _changes(seen)
    done = [msg for t, _, msg, _, _ in records if t == STATUS][-1]
    assert [s.finished for s in done.lists] == [1.0, 1.0]
    resumed = [msg for t, _, msg, _, _ in records if t == ROUTE][-1]
    assert resumed.lists[0].finished == 1.0 and 0.0 < resumed.lists[1].finished < 1.0
    x_rejoin = 7.0 + 3.6 * resumed.lists[1].finished
    assert x_rejoin > CRATE[0] + 0.2  # rejoins past the crate
    poses = [msg for t, _, msg, _, _ in records if t == POSE]
    assert poses[-1].x == pytest.approx(10.6, abs=0.1)
    assert max(abs(p.y - 1.2) for p in poses) > 0.3  # it went around
    assert any(msg.linear > 0.4 for t, _, msg, _, _ in records if t == SPEED)
    assert chain["trace"].popen.poll() is None


#: [s] how far apart a rosbag recorder may stamp two messages sent one after the other
REORDER = 0.1


@pytest.mark.ros
@pytest.mark.process
def test_the_empty_list_cancels_zero_speed_idle_once(chain: dict[str, Any]) -> None:
    def poses_x(n: int) -> list[float]:
        """x of the next ``n`` msg_robot_global_pos, as the system rostopic prints them."""
        out = subprocess.run(["rostopic", "echo", "-n", str(n), "/" + POSE], env={
            **os.environ, **chain["master"].env}, capture_output=True, text=True, timeout=60)
        rows = [line.split("data: ", 1)[1] for line in out.stdout.splitlines()
                if line.startswith("data: ")]
        return [m.RobotPose2D.FromString(bytes(int(v) for v in r.strip("[]").split(","))).x
                for r in rows]

    x0 = poses_x(1)[0]  # where the diagram left it (6.0 when this test runs alone)
    bag = Bag(chain["tmp"] / "cancel.bag", chain["master"])
    try:
        lines = business(chain["master"], "--route", f"{x0:.3f},1.2:{x0 + 2.5:.3f},1.2",
                         "--cancel-after", "1.5")
        assert lines[0].startswith(f"{STATUS} RUNNING"), lines
        assert lines[-1].startswith(f"{STATUS} IDLE"), lines

        # the robot comes to rest: a second of poses (20) within a millimetre
        end = time.monotonic() + 30.0
        while max(xs := poses_x(20)) - min(xs) > 1e-3:
            assert time.monotonic() < end, "the robot did not stop"
        x = xs[-1]
    except BaseException:
        bag.kill()  # no recorder left running after a failure
        raise
    records = bag.read()
    t_cancel = next(t for topic, t, msg, _, _ in records if topic == ROUTE and not msg.lists)
    after = [(topic, msg) for topic, t, msg, _, _ in records if t >= t_cancel]
    # the bag's times are when the recorder's threads took each message, one thread per
    # connection: the zero answering the empty list may be stamped a little before it
    speeds = [(t, (msg.linear, msg.angular)) for topic, t, msg, _, _ in records
              if topic == SPEED and t >= t_cancel - REORDER]
    assert any(s == (0.0, 0.0) for _, s in speeds), "no zero speed answered the empty list"
    assert all(s == (0.0, 0.0) for t, s in speeds if t > t_cancel + REORDER), speeds
    # one publisher, one connection: the statuses are in the order sent, whatever the
    # recorder's threads stamped them (on a busy host the IDLE may be stamped before the empty
    # list that caused it); after the last RUNNING comes one IDLE and nothing else
    statuses = [msg.status for topic, _, msg, _, _ in records if topic == STATUS]
    last_running = max(i for i, s in enumerate(statuses) if s == m.RUNNING)
    assert statuses[last_running + 1:] == [m.IDLE], statuses
    moving = [msg.x for topic, msg in after if topic == POSE]
    assert moving[-1] == pytest.approx(x, abs=1e-3) and x - moving[0] < 0.2
    assert x0 + 0.2 < x < x0 + 2.5 and math.isfinite(x)  # it had moved, and stopped short


@pytest.mark.ros
@pytest.mark.process
def test_bad_envelopes_are_counted_never_a_traceback(chain: dict[str, Any]) -> None:
    """Last in the module: it stops the node to read its counts."""
    env = {**os.environ, **chain["master"].env}
    for msg in ('{type: "GLaserScan", data: [8, 1]}', '{type: "GTraceList", data: [255, 255]}',
                '{type: "GTraceList", data: []}'):  # wrong type, undecodable, map missing
        done = subprocess.run(["rostopic", "pub", "-1", "/" + ROUTE, "lowerbase_msgs/Protobuf",
                               msg], env=env, capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
    trace: Proc = chain["trace"]
    assert trace.popen.poll() is None
    code, err = trace.stop()
    assert code == 0 and "Traceback" not in err, err
    assert f"dropped {ROUTE} 3" in err, err
