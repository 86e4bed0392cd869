"""A short simulated drive recorded to MCAP, with the SimLoop's state at every /odom."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from lowerbase.recording.mcap_writer import McapRecorder
from lowerbase.recording.messages import to_ns
from lowerbase.recording.world import attach_world
from lowerbase.simloop.loop import SimLoop


@dataclass
class Recorded:
    path: Path
    #: per odometry event, after the recorder wrote: (t, ekf pose, raw pose, truth 5-tuple)
    states: list[tuple[float, tuple[float, ...], tuple[float, ...], tuple[float, ...]]] = \
        field(default_factory=list)
    frames: list[tuple[float, int, bytes]] = field(default_factory=list)
    ros_io: list[tuple[str, bytes]] = field(default_factory=list)  #: genpy bytes, if ROS
    counts: dict[str, int] = field(default_factory=dict)


def record_drive(path: Path, *, with_ros_io: bool = False) -> Recorded:
    out = Recorded(path)
    rec = McapRecorder(path)

    def tap(t: float, direction: str, frame_id: int, data: bytes) -> None:
        out.frames.append((t, frame_id, data))
        rec(t, direction, frame_id, data)

    loop = SimLoop(tap=tap)
    tr = loop.mcu.truth
    rec.attach(loop.driver, loop.clock.now, lambda: (tr.x, tr.y, tr.yaw, tr.v, tr.w))

    def after(what: str, core: Any) -> None:
        if what == "odometry":
            odo = core.odometry
            out.states.append((loop.now, core.ekf.pose, (odo.x, odo.y, odo.yaw),
                               (tr.x, tr.y, tr.yaw, tr.v, tr.w)))

    loop.driver.listeners.append(after)
    if with_ros_io:
        loop.driver.listeners.append(_ros_io_listener(loop, out))
    loop.run(1.5)
    loop.drive(0.6, 0.4, 3.0)
    loop.drive(0.0, 0.0, 0.5)
    rec.close()
    out.counts = dict(rec.counts)
    return out


def _ros_io_listener(loop: SimLoop, out: Recorded) -> Any:
    """What the rospy node's ros_io builds for the same events, serialised by genpy."""
    import io

    import rospy

    from lowerbase.driver import ros_io
    from lowerbase.driver.settings import NodeSettings

    s = NodeSettings()
    seq = {"/odom": 0, "/odom_raw": 0, "/imu/data_raw": 0}

    def stamp() -> Any:
        ns = to_ns(loop.now)
        return rospy.Time(ns // 10**9, ns % 10**9)

    def ser(topic: str, msg: Any) -> None:
        if topic in seq:
            seq[topic] += 1
            msg.header.seq = seq[topic]
        buf = io.BytesIO()
        msg.serialize(buf)
        out.ros_io.append((topic, buf.getvalue()))

    def listener(what: str, core: Any) -> None:
        unobserved = core.config.odometry_noise.unobserved_variance
        if what == "odometry":
            odo = core.odometry
            ser("/odom_raw", ros_io.odometry_msg(
                stamp(), s.odom_frame, s.base_frame, (odo.x, odo.y, odo.yaw),
                (odo.linear, odo.angular), odo.pose_covariance, odo.twist_covariance,
                unobserved))
            ekf = core.ekf
            msg = ros_io.odometry_msg(
                stamp(), s.odom_frame, s.base_frame, ekf.pose, ekf.twist,
                [float(v) for v in ekf.pose_covariance().ravel()],
                [float(v) for v in ekf.twist_covariance().ravel()], unobserved)
            ser("/odom", msg)
            from tf2_msgs.msg import TFMessage

            ser("/tf", TFMessage(transforms=[ros_io.transform_from_odometry(msg)]))
        elif what == "imu" and core.imu is not None:
            gyro, accel = core.imu
            ser("/imu/data_raw", ros_io.imu_msg(stamp(), s.imu_frame, gyro, accel,
                                                s.imu_angular_velocity_variance,
                                                s.imu_linear_acceleration_variance))
        elif what == "status_code":
            ser("/status_code", ros_io.status_code_msg(core.status_code))

    return listener


@pytest.fixture(scope="package")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    return record_drive(tmp_path_factory.mktemp("mcap") / "drive.mcap")


def record_world(path: Path, duration: float = 2.0) -> dict[str, int]:
    """The library's warehouse_localization, its first ``duration`` s, recorded to MCAP with
    the world's topics (what `lowerbase scenario run` writes); the message counts."""
    import dataclasses

    from lowerbase.scenarios.catalog import library
    from lowerbase.scenarios.runner import SimHarness, run_scenario
    from lowerbase.scenarios.wheeled import load_scenario

    sc = dataclasses.replace(load_scenario(library()["warehouse_localization"]),
                             duration=duration, expectations=())
    rec = McapRecorder(path)
    harness = SimHarness(sc, tap=rec)
    rec.attach(harness.driver, harness.now, harness.truth)
    attach_world(rec, harness.world)
    try:
        run_scenario(sc, harness)
    finally:
        harness.close()
        rec.close()
    return dict(rec.counts)


def record_tasks(path: Path, duration: float = 4.0) -> dict[str, int]:
    """The library's transport task scenario, its first ``duration`` s (the task is accepted
    and planned at 1 s), recorded to MCAP as `lowerbase scenario run tasks/transport` does;
    the message counts."""
    import dataclasses

    from lowerbase.scenarios.tasks import library_tasks, load_tasks_scenario
    from lowerbase.scenarios.tasks_run import run_tasks_scenario

    sc = dataclasses.replace(load_tasks_scenario(library_tasks()["transport"]),
                             duration=duration, expects=[])
    with McapRecorder(path) as rec:
        run_tasks_scenario(sc, publisher=rec)
    return dict(rec.counts)
