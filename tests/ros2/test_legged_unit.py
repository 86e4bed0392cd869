"""The ROS-free parts of ``lowerbase robot --robot legged --sim-time --ros2`` (run in the ROS 1
venv, without rclpy): the command line's choice of robot, and :class:`LeggedLockstep` on a
``side`` (how it reaches ROS: ROS 1's or ROS 2's) that only records what it is asked."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path
from types import SimpleNamespace as NS
from typing import Any

import pytest

from lowerbase.cli import main
from lowerbase.robot.lockstep import LockstepOptions, LockstepRobot
from lowerbase.robot.lockstep_legged import LeggedLockstep
from lowerbase.ros1.wire import Switchboard


@pytest.mark.parametrize("sim_time", [["--sim-time"], []])
@pytest.mark.parametrize(("robot", "make"), [("legged", LeggedLockstep),
                                             ("wheeled", LockstepRobot)])
def test_ros2_runs_the_robot_asked_for(monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture[str], robot: str,
                                       make: Any, sim_time: list[str]) -> None:
    """``--robot legged --ros2`` is no longer refused: lockstep_ros2.run builds the legged
    robot (the wheeled one by default), with the options of ROS 1's (``--paused`` too).
    Without --sim-time it is the same lockstep robot, and one line says so."""
    import lowerbase.driver.ros2_node as ros2_node
    import lowerbase.robot.lockstep_ros2 as lockstep_ros2
    from lowerbase.cli.robot import ROS2_SIM_TIME

    calls: list[tuple[Any, ...]] = []
    monkeypatch.setattr(ros2_node, "import_rclpy", lambda: None)
    monkeypatch.setattr(lockstep_ros2, "run", lambda opts, speed, ros_args, duration, make,
                        paused: calls.append((opts, speed, duration, make, paused)) or 0)
    assert main(["robot", "--robot", robot, "--ros2", *sim_time, "--speed", "max",
                 "--duration", "3", "--soc", "55", "--paused"]) == 0
    [(opts, speed, duration, made, paused)] = calls
    assert made is make and speed is None and duration == 3.0 and paused
    assert opts.soc == 55.0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ([] if sim_time else [ROS2_SIM_TIME])


class Wire:
    """A face's wire that records what it is asked for (names as given)."""

    def __init__(self, side: RecordingSide, node: str) -> None:
        self.side, self.node = side, node

    def publisher(self, name: str, cls: Any, **kwargs: Any) -> Any:
        return NS(publish=lambda msg: self.side.published.append((name, msg)))

    def subscriber(self, name: str, cls: Any, callback: Any, **kwargs: Any) -> Any:
        self.side.subscribed.append(name)
        return NS(unregister=lambda: None)

    def service(self, name: str, cls: Any, handler: Any) -> Any:
        self.side.services[name] = handler
        return NS(shutdown=lambda: None)


def _message(**fields: Any) -> NS:
    return NS(**fields)


class RecordingSide:
    """A side (:class:`~lowerbase.robot.lockstep.Ros1Side`'s interface) that records."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.clock: list[float] = []
        self.published: list[tuple[str, Any]] = []
        self.subscribed: list[str] = []
        self.services: dict[str, Any] = {}
        self.faces: list[str] = []
        self.wires: list[str] = []
        srv = NS(**{f"{n}{part}": _message for n in ("SetWaypoints", "GetWaypoints",
                                                     "AppendWaypoint", "SetLaserMap",
                                                     "SetListen")
                    for part in ("", "Response")})
        self.ros = NS(rospy=None, Twist=object, Joy=object, Trigger=object,
                      TriggerResponse=_message, srv=srv,
                      msg=NS(RobotState=_message, ActuatorState=_message, Waypoint=_message))

    def board(self) -> Any:
        return Switchboard(None, tf=object())

    def wire(self, board: Any, name: str) -> Any:
        self.wires.append(name)
        return Wire(self, name)

    def face_ros(self, face: str) -> Any:
        self.faces.append(face)
        return self.ros

    def set_time(self, now: float) -> None:
        self.times.append(now)

    def clock_publisher(self) -> Any:
        return "clock"

    def clock_sender(self, publisher: Any) -> Any:
        assert publisher == "clock"
        return self.clock.append


def test_legged_lockstep_reaches_ros_through_its_side(monkeypatch: pytest.MonkeyPatch,
                                                      tmp_path: Path) -> None:
    """Everything the legged robot says to ROS goes through ``side`` (no rospy here): its
    face's wire and message types, ROS time, /clock every 10 ms and robot_state every 20 ms
    of simulated time; a service answers through the side's types."""
    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    side = RecordingSide()
    robot = LeggedLockstep(LockstepOptions(), None, side)
    assert (tmp_path / "maps").is_dir()  # set_map's directory is made
    assert side.faces == ["legged"] and side.wires == ["legged_driver"]
    robot.advertise()
    assert side.subscribed == ["/cmd_vel"]
    assert {"~walk", "~stand", "~sit", "planning/set_waypoints", "set_map"} <= \
        set(side.services)
    robot.run_periods(100)  # 0.1 s
    assert side.clock == pytest.approx([k / 100 for k in range(10)])
    assert side.times[-1] == pytest.approx(0.1)
    assert all(b >= a for a, b in pairwise(side.times))
    states = [msg for name, msg in side.published if name == "robot_state"]
    assert len(states) == 5 and len(states[0].actuator_states) == 12
    answer = side.services["~walk"](None)
    assert answer.success and answer.message.endswith("-> IN_CONTROL")
    robot.shutdown()
