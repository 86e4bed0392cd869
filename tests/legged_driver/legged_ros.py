"""ROS fixtures of the legged robot's tests: the generated message packages and a rosmaster.

Imported by the test modules that need them (``from tests.legged_driver.legged_ros import
...``) rather than from a conftest.py, so that the folder can hold other suites' conftest
freely.
"""

from __future__ import annotations

import importlib
import shutil
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from tests.conftest import every_msggen_package
from tests.driver.conftest import ROS_MODULES, RosMaster, is_ci, require_ros

LEGGED_PKG = "lowerbase_legged_msgs"
_HIDDEN = ("woosh_msgs", LEGGED_PKG)


@pytest.fixture(scope="module")
def legged_build(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Every msggen package generated into a fresh directory, first on ``sys.path``.

    Packages already importable (the venv's .pth to build/ros) are hidden meanwhile, so that
    the tests check what this checkout generates.
    """
    require_ros((*ROS_MODULES, "sensor_msgs.msg"))
    with every_msggen_package(tmp_path_factory.mktemp("legged_ros"), _HIDDEN) as path:
        yield path


@pytest.fixture(scope="module")
def legged_msgs(legged_build: Path) -> ModuleType:
    module = importlib.import_module(f"{LEGGED_PKG}.msg")
    assert Path(module.__file__ or "").is_relative_to(legged_build), module.__file__
    return module


@pytest.fixture(scope="module")
def legged_srvs(legged_build: Path) -> ModuleType:
    return importlib.import_module(f"{LEGGED_PKG}.srv")


@pytest.fixture(scope="module")
def legged_master(
    tmp_path_factory: pytest.TempPathFactory, legged_build: Path
) -> Iterator[RosMaster]:
    """A private rosmaster whose ``env`` finds the generated packages."""
    require_ros((*ROS_MODULES, "rosgraph"))
    if shutil.which("rosmaster") is None:
        reason = "rosmaster is not on PATH; run scripts/install-ros.sh as root"
        if is_ci():
            pytest.fail(f"CI=true requires ROS: {reason}", pytrace=False)
        pytest.skip(reason)
    master = RosMaster(tmp_path_factory.mktemp("legged_ros_home"),
                       share_dirs=[legged_build / "share"], python_dirs=[legged_build])
    try:
        yield master
    finally:
        master.stop()


class ScriptedLegs:
    """A scripted lower computer on the four leg buses (a thread of the test process).

    Every ``period`` it sends each actuator's MotorReply (position ``0.05 * index`` rad,
    temperature ``30 + index``) on its leg bus and the body frames on bus 0; it follows
    LocomotionRequests along the real state table (``body.ALLOWED``; MOTOR_ENABLED requested
    from MOTOR_READY passes through MOTOR_COMMUTATION, SITDOWN_MODE ends in MOTOR_ENABLED, one
    period each) and, while IN_CONTROL, walks an ideal base at the commanded body velocity.
    ``commands`` keeps every BodyVelocityCommand received (vx, vy, yaw rate).
    """

    def __init__(self, configs: list[dict[str, object]], period: float = 0.02) -> None:
        import math
        import threading

        from lowerbase.legged.body import ALLOWED
        from lowerbase.protocol.legged import JOINT_NAMES, LocomotionState, legged_codec
        from lowerbase.transport import open_bus

        self._math, self.allowed, self.S = math, ALLOWED, LocomotionState
        self.codec = legged_codec()
        self.buses = [open_bus(dict(c)) for c in configs]
        self.n_joints = len(JOINT_NAMES)
        self.period = period
        self.state = LocomotionState.COMM_DISABLED
        self.x = self.y = self.yaw = 0.0
        self.commands: list[tuple[float, float, float]] = []
        self.requests: list[int] = []
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _send(self, bus: int, name: str, **signals: float) -> None:
        import can

        msg = self.codec.message(name)
        values = signals if name == "MotorReply" else {
            s.name: 0 for s in msg.signal_sets[0]} | signals
        self.buses[bus].send(can.Message(arbitration_id=msg.frame_id, is_extended_id=False,
                                         data=self.codec.encode(name, values)))

    def _receive(self) -> None:
        S = self.S
        while (m := self.buses[0].recv(0)) is not None:
            try:
                name, s = self.codec.decode(m.arbitration_id, bytes(m.data))
            except Exception:
                continue
            with self.lock:
                if name == "BodyVelocityCommand":
                    self.commands.append((float(s["Vx"]), float(s["Vy"]), float(s["YawRate"])))
                elif name == "LocomotionRequest":
                    want = S(int(s["Request"]))
                    self.requests.append(int(want))
                    if want in self.allowed[self.state]:
                        from_ready = self.state in (S.MOTOR_READY, S.MOTOR_DISABLED)
                        self.state = (S.MOTOR_COMMUTATION if want == S.MOTOR_ENABLED
                                      and from_ready else want)
        for bus in self.buses[1:]:
            while bus.recv(0) is not None:
                pass

    def _step(self) -> None:
        S, math = self.S, self._math
        with self.lock:
            if self.state in (S.MOTOR_COMMUTATION, S.SITDOWN_MODE):
                self.state = S.MOTOR_ENABLED
            vx, vy, wz = self.commands[-1] if self.commands else (0.0, 0.0, 0.0)
            if self.state != S.IN_CONTROL:
                vx = vy = wz = 0.0
            c, s = math.cos(self.yaw), math.sin(self.yaw)
            self.x += (c * vx - s * vy) * self.period
            self.y += (s * vx + c * vy) * self.period
            self.yaw += wz * self.period
            state, x, y, yaw = self.state, self.x, self.y, self.yaw
        for i in range(self.n_joints):
            bus, motor = divmod(i, 3)
            p = ("Hip", "Thigh", "Calf")[motor]
            self._send(bus, "MotorReply", MotorId=motor + 1, **{
                p + "Position": 0.05 * i, p + "Velocity": 0.0, p + "Torque": 0.0},
                Temperature=30 + i, Error=0)
        self._send(0, "LocomotionStatus", State=int(state), LastRequest=15, FaultJoint=15)
        self._send(0, "BasePosition", X=x, Y=y, Z=0.3)
        self._send(0, "BaseOrientation", QX=0.0, QY=0.0, QZ=math.sin(yaw / 2),
                   QW=math.cos(yaw / 2))
        self._send(0, "BmsPack", Voltage=50.4, Current=-3.0, Soc=80)
        self._send(0, "BmsCell", CellVoltageMax=4.2, CellVoltageMin=4.1, TempMax=30,
                   TempMin=28)
        self._send(0, "BodyTemperature", Body=36.5, ActuatorMax=41.0, HottestJoint=11)

    def _run(self) -> None:
        while not self.stop.is_set():
            self._receive()
            self._step()
            self.stop.wait(self.period)  # the peer's own pace, not a test timing

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5)
        for bus in self.buses:
            bus.shutdown()
