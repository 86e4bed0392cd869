"""A task scenario's MCAP (`lowerbase scenario run tasks/NAME`, `lowerbase demo`): the library's
transport task recorded through run_and_report, decoded with mcap-ros1-support's decoder and
rosbags; /robot_status is the run's published robot_status, the plans the navigator's, the
truth the run's samples; the run is the same with and without the recording; a WebSocket
client sees /robot_status live. The CLI: --mcap/--no-mcap/--foxglove on task scenarios."""

from __future__ import annotations

import dataclasses
import math
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros1.decoder import DecoderFactory

from lowerbase.cli import main
from lowerbase.recording.live import FoxgloveSink
from lowerbase.recording.messages import to_ns
from lowerbase.recording.publisher import RunPublisher
from lowerbase.recording.ros1_types import ros1_types
from lowerbase.reports.tasks import run_and_report
from lowerbase.scenarios.tasks import library_tasks, load_tasks_scenario
from lowerbase.scenarios.tasks_run import SAMPLE_COLUMNS, TasksResult, run_tasks_scenario
from lowerbase.tasks.model import Status
from tests.recording.foxglove_client import FoxgloveClient

TOPICS = {"/odom": "nav_msgs/Odometry", "/odom_raw": "nav_msgs/Odometry",
          "/imu/data_raw": "sensor_msgs/Imu", "/battery": "woosh_msgs/Battery",
          "/driver_base/bms": "woosh_msgs/BMS", "/status_code": "std_msgs/UInt64",
          "/tf": "tf2_msgs/TFMessage", "/ground_truth/odom": "nav_msgs/Odometry",
          "/map": "nav_msgs/OccupancyGrid", "/scan": "sensor_msgs/LaserScan",
          "/amcl_pose": "geometry_msgs/PoseWithCovarianceStamped",
          "/ground_truth/pose": "geometry_msgs/PoseStamped",
          "/move_base/NavfnROS/plan": "nav_msgs/Path",
          "/robot_status": "woosh_msgs/RobotStatus", "/can/frames": "can_msgs/Frame"}


@dataclasses.dataclass
class TaskRun:
    path: Path
    result: TasksResult
    plain: TasksResult  #: the same scenario without any recording
    decoded: dict[str, list[tuple[int, Any]]]  #: topic -> [(log ns, mcap-ros1-support msg)]


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


@pytest.fixture(scope="module")
def task_run(tmp_path_factory: pytest.TempPathFactory) -> TaskRun:
    out = tmp_path_factory.mktemp("tasks")
    sc = load_tasks_scenario(library_tasks()["transport"])
    result, summary = run_and_report(sc, out / "report", mcap=out / "transport.mcap")
    assert summary is not None and result.passed
    decoded: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with (out / "transport.mcap").open("rb") as f:
        for _, channel, msg, ros in make_reader(
                f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                    topics=list(TOPICS)):
            decoded[channel.topic].append((msg.log_time, ros))
    return TaskRun(out / "transport.mcap", result, run_tasks_scenario(sc), decoded)


def test_every_topic_with_its_type(task_run: TaskRun) -> None:
    with task_run.path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert {t: types.get(t) for t in TOPICS} == TOPICS
    duration = task_run.result.scenario.duration
    assert abs(len(task_run.decoded["/odom"]) - 50 * duration) < 60  # 50 Hz, after the link
    assert abs(len(task_run.decoded["/scan"]) - 25 * duration) <= 2


def test_robot_status_is_what_the_run_published(task_run: TaskRun) -> None:
    got = task_run.decoded["/robot_status"]
    history = task_run.result.history
    assert len(got) == len(history) >= 5
    for (ns, msg), (t, status) in zip(got, history, strict=True):
        assert ns == to_ns(t)
        fields = {k: getattr(msg, k) for k in Status().fields()}
        assert fields == status.fields()
    # a real task: executing, then completed, with the reasons in msg
    states = [msg.task_state for _, msg in got if msg.task_id == 1]
    assert states[0] == 3 and states[-1] == 7
    # the same bytes rosbags' ROS1 serialiser gives (an independent encoder)
    types = ros1_types()
    raw = _raw(task_run.path, "/robot_status")
    for data, (_, status) in zip(raw, history, strict=True):
        msg = types.deserialize(data, "woosh_msgs/RobotStatus")
        assert types.serialize(msg) == data and msg.msg == status.msg


def _raw(path: Path, topic: str) -> list[bytes]:
    with path.open("rb") as f:
        return [m.data for _, _, m in make_reader(f).iter_messages(topics=[topic])]


def test_plans_are_the_navigators(task_run: TaskRun) -> None:
    got = task_run.decoded["/move_base/NavfnROS/plan"]
    plans = task_run.result.plans
    assert len(got) == len(plans) >= 1
    for (ns, msg), (t, poses) in zip(got, plans, strict=True):
        assert ns == to_ns(t) and msg.header.frame_id == "map"
        assert len(msg.poses) == len(poses) > 2
        for p, (x, y, yaw) in zip(msg.poses, poses, strict=True):
            assert (p.pose.position.x, p.pose.position.y) == (x, y)
            assert _yaw(p.pose.orientation) == pytest.approx(yaw, abs=1e-9)


def test_ground_truth_is_the_runs(task_run: TaskRun) -> None:
    """/ground_truth/pose (map frame) at each whole second equals the run's sampled truth."""
    truth = {ns: msg.pose for ns, msg in task_run.decoded["/ground_truth/pose"]}
    cols = {c: i for i, c in enumerate(SAMPLE_COLUMNS)}
    checked, moved = 0, 0.0
    for row in task_run.result.samples:
        ns = to_ns(row[cols["t"]])
        if ns in truth:
            p = truth[ns]
            assert (p.position.x, p.position.y) == pytest.approx(
                (row[cols["truth_x"]], row[cols["truth_y"]]), abs=1e-9)
            assert _yaw(p.orientation) == pytest.approx(row[cols["truth_yaw"]], abs=1e-9)
            checked += 1
            moved = max(moved, math.hypot(p.position.x - truth[min(truth)].position.x,
                                          p.position.y - truth[min(truth)].position.y))
    assert checked >= 50 and moved > 2.0  # the robot drove to R1
    # /ground_truth/odom next to each /odom, at the same stamp
    odom = [ns for ns, _ in task_run.decoded["/odom"]]
    assert [ns for ns, _ in task_run.decoded["/ground_truth/odom"]] == odom


def test_recording_does_not_change_the_run(task_run: TaskRun) -> None:
    a, b = task_run.result, task_run.plain
    assert a.history == b.history and [t for t, _ in a.history] == [t for t, _ in b.history]
    np.testing.assert_array_equal(np.array(a.samples), np.array(b.samples))  # NaN == NaN
    assert a.plans == b.plans and a.responses == b.responses
    assert a.sim.world.loop.driver.ekf.pose == b.sim.world.loop.driver.ekf.pose


def test_robot_status_live_over_websocket() -> None:
    """A client subscribed to /robot_status gets every status published after that, with the
    run's fields; the run streams on the simulated clock, held while the client subscribes."""
    sc = dataclasses.replace(load_tasks_scenario(library_tasks()["transport"]), duration=40.0)
    live = FoxgloveSink("127.0.0.1", 0)
    publisher = RunPublisher([live])
    client: FoxgloveClient | None = None
    since: list[float] = []

    def progress(t: float, sim: Any) -> None:
        nonlocal client
        if client is None and t >= 0.5:  # the first status is out: the channel exists
            client = FoxgloveClient(live.url)
            client.pump_until(lambda: "/robot_status" in client.channels)  # type: ignore
            client.subscribe("/robot_status")
            deadline = time.monotonic() + 20.0
            while not live.subscribed("/robot_status"):
                assert time.monotonic() < deadline, "the subscription never arrived"
                time.sleep(0.005)
            since.append(t)

    try:
        result = run_tasks_scenario(sc, progress=progress, publisher=publisher)
        assert client is not None and since
        after = [(t, s) for t, s in result.history if t >= since[0]]
        assert len(after) >= 4  # the task: accepted, navigation, transport, completed
        client.pump_until(lambda: len(client.messages.get("/robot_status", [])) == len(after))
    finally:
        publisher.close()
        if client is not None:
            client.close()
    types = ros1_types()
    for (ns, payload), (t, status) in zip(client.messages["/robot_status"], after, strict=True):
        msg = types.deserialize(payload, "woosh_msgs/RobotStatus")
        assert ns == to_ns(t)
        assert {k: getattr(msg, k) for k in Status().fields()} == status.fields()
    assert client.channels["/robot_status"]["schemaName"] == "woosh_msgs/RobotStatus"


def test_cli_writes_run_mcap_by_default_and_takes_no_mcap(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rep"
    code = main(["scenario", "run", "tasks/parking", "--out", str(out)])
    stdout = capsys.readouterr().out
    assert code == 0, stdout
    assert f"mcap: {out / 'run.mcap'}" in stdout
    with (out / "run.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert "/robot_status" in {c.topic for c in summary.channels.values()}
    out2 = tmp_path / "rep2"
    assert main(["scenario", "run", "tasks/parking", "--out", str(out2), "--no-mcap"]) == 0
    assert "mcap:" not in capsys.readouterr().out and not (out2 / "run.mcap").exists()


@pytest.mark.parametrize("flags, text", [
    (["--mcap", "x.bag"], "--mcap x.bag: the file name must end in .mcap"),
    (["--foxglove", "1.2.3.4:99999"], "the port must be a number"),
])
def test_cli_bad_recording_flags_are_one_line(tmp_path: Path, flags: list[str], text: str,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rep"
    assert main(["scenario", "run", "tasks/transport", "--out", str(out), *flags]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and text in err[0], err
    assert not out.exists()


def test_demo_bad_foxglove_is_one_line(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--out", str(tmp_path / "d"), "--foxglove", "host:port"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the port must be a number" in err[0], err
    assert not (tmp_path / "d").exists()
