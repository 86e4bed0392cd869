"""The whole chain for black-box ROS tests, each part a process on a real rosmaster: `lowerbase
world --ground-truth` (its /amcl_pose the emulator's true pose), `lowerbase emulate
--truth-udp`, `lowerbase driver` on a loopback multicast bus, then whatever the test adds
(:meth:`Chain.start`; :func:`nav_chain` adds navigation, optionally tasks, and a NavClient).
Every process is stopped in reverse order when the ``with`` block ends. The ROS fixtures stay
in tests/driver/conftest.py (``require_ros``, ``ros_master``): call ``require_ros`` first."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tests.conftest import Proc, bus_cli_args, free_udp_port
from tests.navigation.ros_client import NavClient


def write_crate(path: Path, center: tuple[float, float]) -> Path:
    """An obstacles file with one 0.4 m crate the map does not know at ``center``."""
    path.write_text('[[obstacles]]\nkind = "box"\nname = "crate"\n'
                    f"center = [{center[0]}, {center[1]}]\nsize = [0.4, 0.4]\n")
    return path


class Chain:
    """The chain's processes, started in order, stopped in reverse."""

    def __init__(self, env: dict[str, str]) -> None:
        self.env = env
        self.procs: list[Proc] = []

    def start(self, args: list[str], ready: str | None = None, timeout: float = 30.0) -> Proc:
        """``lowerbase *args``, waited for a stdout line containing ``ready`` (if given)."""
        proc = Proc(args, self.env)
        self.procs.append(proc)
        if ready is not None:
            proc.wait_for(ready, timeout=timeout)
        return proc

    def stop(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()


@contextmanager
def ros_chain(env: dict[str, str], place: Sequence[str], channel: str,
              timeout: float = 30.0) -> Iterator[Chain]:
    """world, emulate and driver on ``place`` (map, obstacles, initial pose flags), the bus
    on multicast group ``channel`` (one per test module); each ready within ``timeout``."""
    chain = Chain(env)
    try:
        bus = bus_cli_args({"interface": "udp_multicast", "channel": channel,
                            "port": free_udp_port(), "hop_limit": 0})
        truth_port = free_udp_port()
        chain.start(["world", *place, "--truth-udp", str(truth_port), "--ground-truth",
                     "--no-camera"], "on ROS master", timeout)
        chain.start(["emulate", *bus, *place, "--truth-udp", f"127.0.0.1:{truth_port}"])
        chain.start(["driver", *bus], "ROS master", timeout)
        yield chain
    finally:
        chain.stop()


@contextmanager
def nav_chain(env: dict[str, str], tmp: Path, place: Sequence[str], channel: str,
              topics: Sequence[tuple[str, str]], tasks: Sequence[str] | None = None,
              ) -> Iterator[tuple[Chain, NavClient]]:
    """:func:`ros_chain` on empty_room plus `lowerbase navigation` (ready), with ``tasks``
    the flags of `lowerbase tasks` (then also waited for robot_state idle on /robot_status,
    which must be among ``topics``), and a NavClient subscribed to ``topics`` (name, type)."""
    with ros_chain(env, place, channel) as chain:
        client: NavClient | None = None
        try:
            chain.start(["navigation", "--map", "empty_room", "--no-camera"], "ready", 60.0)
            if tasks is not None:
                chain.start(["tasks", "--map", "empty_room", *tasks], "on ROS master")
            client = NavClient(tmp, env)
            for topic, kind in topics:
                client.ask(op="sub", topic=topic, type=kind)
            if tasks is not None:
                client.wait_last("/robot_status", _idle, 60.0, "robot_state idle")
            yield chain, client
        finally:
            if client is not None:
                client.close()


def _idle(msg: dict[str, Any]) -> bool:
    return bool(msg["robot_state"] == 2)  # woosh_msgs/RobotStatus IDLE
