"""The legged lower computer as a black box on its buses: an upper-side client on four virtual
buses walks the robot with LocomotionRequest and BodyVelocityCommand frames only (the runner on
the simulated clock), and ``lowerbase emulate --robot legged`` as a process on udp_multicast
loopback (frames on all four ports, clean exit on Ctrl-C)."""

from __future__ import annotations

import time
import uuid
from collections import Counter
from typing import Any

import can
import pytest

from lowerbase.clock import SimClock
from lowerbase.errors import ConfigError
from lowerbase.legged.lower import LeggedLower
from lowerbase.legged.profile import LeggedProfile
from lowerbase.legged.runner import close_buses, leg_bus_configs, open_legged, run_legged
from lowerbase.protocol.legged import REPLY_ID, LocomotionState, legged_codec
from lowerbase.transport import open_bus
from tests.conftest import TEST_GROUP, free_udp_port

S = LocomotionState
CODEC = legged_codec()
#: the client's plan: the states it requests in turn, each from the state before it
PLAN = [S.COMM_ENABLED, S.MOTOR_READY, S.MOTOR_ENABLED, S.STANDING_MODE, S.IN_CONTROL]
BEFORE = {S.COMM_ENABLED: S.COMM_DISABLED, S.MOTOR_READY: S.COMM_ENABLED,
          S.MOTOR_ENABLED: S.MOTOR_READY, S.STANDING_MODE: S.MOTOR_ENABLED,
          S.IN_CONTROL: S.STANDING_MODE}


class UpperClient:
    """Knows only the wire: reads LocomotionStatus/BasePosition/MotorReply, sends requests
    and body velocity commands."""

    def __init__(self, buses: list[can.BusABC]) -> None:
        self.buses = buses
        self.seen: Counter[tuple[int, str]] = Counter()
        self.status: dict[str, Any] = {}
        self.position: dict[str, Any] = {}
        self.step = 0
        self.plan = list(PLAN)
        self.walk_started: float | None = None

    def send(self, name: str, values: dict[str, float | int]) -> None:
        msg = CODEC.message(name)
        self.buses[0].send(can.Message(arbitration_id=msg.frame_id,
                                       data=msg.encode({**values, "Counter": 0}),
                                       is_extended_id=False))

    def __call__(self, lower: LeggedLower) -> None:
        t = lower.clock.now()
        for k, bus in enumerate(self.buses):
            while (m := bus.recv(0.0)) is not None:
                name, s = CODEC.decode(m.arbitration_id, bytes(m.data))
                self.seen[(k, name)] += 1
                if name == "LocomotionStatus":
                    self.status = s
                elif name == "BasePosition":
                    self.position = s
        self.step += 1
        if self.step % 20:
            return
        state = self.status.get("State")
        while self.plan and state == self.plan[0]:  # reached: on to the next
            self.plan.pop(0)
        if self.plan and state == BEFORE[self.plan[0]]:  # (re)sent until reached: BUSY while
            self.send("LocomotionRequest", {"Request": int(self.plan[0])})  # standing up
        if state == S.IN_CONTROL:
            if self.walk_started is None:
                self.walk_started = t
            self.send("BodyVelocityCommand", {"Vx": 0.5, "Vy": 0.0, "YawRate": 0.0})


def test_upper_client_walks_the_robot_over_virtual_buses() -> None:
    channel = f"legged-{uuid.uuid4().hex}"
    clock = SimClock()
    lower, buses = open_legged(LeggedProfile(), clock,
                               {"interface": "virtual", "channel": channel})
    mine = [can.Bus(interface="virtual", channel=f"{channel}/{k}") for k in range(4)]
    client = UpperClient(mine)
    try:
        run_legged(lower, buses, clock, duration=6.0, on_step=client)
    finally:
        close_buses([*buses, *mine])
        lower.shutdown()
    assert client.status["State"] == S.IN_CONTROL and not client.plan
    assert client.walk_started is not None
    walked = 6.0 - client.walk_started
    # 0.5 m/s less the 0.25 s acceleration ramp's 0.0625 m, within a 20 ms frame
    assert client.position["X"] == pytest.approx(0.5 * walked - 0.0625, abs=0.03)
    for k in range(4):
        assert client.seen[(k, "MotorReply")] > 3 * 1000  # every leg answers at 3 kHz
    assert client.seen[(0, "BmsPack")] == 6
    assert lower.stats["rx_malformed"] == 0 and lower.stats["rx_wrong_bus"] == 0


def test_leg_bus_configs() -> None:
    udp = leg_bus_configs({"interface": "udp_multicast", "channel": TEST_GROUP, "port": 50000})
    assert [c["port"] for c in udp] == [50000, 50001, 50002, 50003]
    assert [c["channel"] for c in leg_bus_configs({"interface": "virtual", "channel": "x"})] \
        == ["x/0", "x/1", "x/2", "x/3"]
    can4 = leg_bus_configs({"interface": "socketcan", "channel": "can0, can1,can2,can3"})
    assert [c["channel"] for c in can4] == ["can0", "can1", "can2", "can3"]
    with pytest.raises(ConfigError, match="-c can0,can1,can2,can3"):
        leg_bus_configs({"interface": "socketcan", "channel": "can0"})
    with pytest.raises(ConfigError, match="lower port"):
        leg_bus_configs({"interface": "udp_multicast", "port": 65534})


def test_emulate_robot_legged_process(lowerbase_proc: Any) -> None:
    port = free_udp_port()
    config = {"interface": "udp_multicast", "channel": TEST_GROUP, "hop_limit": 0}
    proc = lowerbase_proc("emulate", "--robot", "legged", "-i", "udp_multicast", "-c",
                          TEST_GROUP, "--bus-kwargs", f"port={port}", "hop_limit=0")
    line = proc.wait_for("Ctrl-C stops")
    assert f"ports {port}..{port + 3}" in line
    buses = [open_bus({**config, "port": port + k}) for k in range(4)]
    try:
        seen: Counter[tuple[int, int]] = Counter()
        request = CODEC.message("LocomotionRequest")
        buses[0].send(can.Message(arbitration_id=request.frame_id, is_extended_id=False,
                                  data=request.encode({"Request": 1, "Counter": 0})))
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            for k, bus in enumerate(buses):
                while (m := bus.recv(0.0)) is not None:
                    seen[(k, m.arbitration_id)] += 1
            time.sleep(0.005)
    finally:
        close_buses(buses)
    code, err = proc.stop()
    assert code == 0, err
    assert "stopped after" in err and "Traceback" not in err
    assert "state COMM_ENABLED" in err
    for k in range(4):
        assert seen[(k, REPLY_ID)] > 0 and seen[(k, 1)] > 0, (k, seen)
    assert seen[(0, CODEC.message("Heartbeat").frame_id)] >= 1
    assert seen[(0, CODEC.message("LocomotionStatus").frame_id)] > 10


@pytest.mark.parametrize("flag", [["--foxglove"], ["--map", "warehouse"], ["--fleet", "2"]])
def test_wheeled_only_options_are_refused_in_one_line(
        flag: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    from lowerbase.cli import main

    assert main(["emulate", "--robot", "legged", "--duration", "1", *flag]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--robot legged does not take" in err[0], err
