"""Shared helpers of the driver tests: ROS availability and the generated woosh_msgs.

``require_ros()`` skips a test when ROS1's Python side is missing, with the reason, except
under ``CI=true``, where a missing ROS is a failure: CI installs it (scripts/install-ros.sh) and
must not go green by skipping. Use it directly or through the ``ros`` / ``woosh_msgs`` fixtures.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from tests.conftest import first_on_path

ROS_MODULES = (
    "rospy",
    "genpy",
    "genmsg",
    "std_msgs.msg",
    "geometry_msgs.msg",
    "actionlib_msgs.msg",
)


def is_ci() -> bool:
    """True when a missing ROS must fail the run: CI (``CI=true`` or ``CI=1``), unless the run
    says it has no ROS on purpose (``LOWERBASE_WITHOUT_ROS=1``, as ``make test-oldest`` does)."""
    if os.environ.get("LOWERBASE_WITHOUT_ROS", "").lower() in ("true", "1"):
        return False
    return os.environ.get("CI", "").lower() in ("true", "1")


def ros_missing_reason(modules: tuple[str, ...] = ROS_MODULES) -> str | None:
    """Why ROS is unusable here, or None when every module in ``modules`` imports."""
    missing = []
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            missing.append(f"{name} ({exc})")
    if not missing:
        return None
    return (
        "ROS1 Python packages missing: "
        + ", ".join(missing)
        + "; run scripts/install-ros.sh as root or source /opt/ros/noetic/setup.bash"
    )


def require_ros(modules: tuple[str, ...] = ROS_MODULES) -> None:
    """Skip the calling test when ROS is missing; fail instead under CI=true."""
    reason = ros_missing_reason(modules)
    if reason is None:
        return
    if is_ci():
        pytest.fail(f"CI=true requires ROS: {reason}", pytrace=False)
    pytest.skip(reason)


@pytest.fixture
def ros() -> None:
    """Skip (fail under CI) unless rospy, genpy and the standard messages import."""
    require_ros()


def _is_woosh(module_name: str) -> bool:
    return module_name == "woosh_msgs" or module_name.startswith("woosh_msgs.")


@pytest.fixture(scope="session")
def woosh_msgs_build(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """woosh_msgs generated into a fresh directory that is put first on ``sys.path``.

    A woosh_msgs already importable (a venv .pth to build/ros) is hidden for the session so
    that the tests check what this checkout generates.
    """
    require_ros()
    from lowerbase.driver import msggen

    out = tmp_path_factory.mktemp("ros")
    msggen.generate(out)
    with first_on_path(out, _is_woosh) as path:
        yield path


@pytest.fixture(scope="session")
def woosh_msgs(woosh_msgs_build: Path) -> ModuleType:
    """The generated ``woosh_msgs.msg`` module."""
    module = importlib.import_module("woosh_msgs.msg")
    assert Path(module.__file__ or "").is_relative_to(woosh_msgs_build), module.__file__
    return module


@pytest.fixture(scope="session")
def woosh_srvs(woosh_msgs_build: Path) -> ModuleType:
    """The generated ``woosh_msgs.srv`` module."""
    return importlib.import_module("woosh_msgs.srv")


# -- a ROS master of the tests' own -------------------------------------------------------------


class RosMaster:
    """A ``rosmaster --core`` on 127.0.0.1 and a free port, with an environment that points
    ROS clients (subprocesses) at it and keeps their files under ``home``."""

    def __init__(self, home: Path, share_dirs: list[Path], python_dirs: list[Path]) -> None:
        import socket
        import subprocess

        from lowerbase.transport import free_loopback_port

        self.port = free_loopback_port(socket.SOCK_STREAM)
        self.uri = f"http://127.0.0.1:{self.port}"
        home.mkdir(parents=True, exist_ok=True)
        package_path = [str(p) for p in share_dirs]
        if os.environ.get("ROS_PACKAGE_PATH"):
            package_path.append(os.environ["ROS_PACKAGE_PATH"])
        python_path = [str(p) for p in python_dirs]
        if os.environ.get("PYTHONPATH"):
            python_path.append(os.environ["PYTHONPATH"])
        #: what a ROS client process needs (merge into os.environ)
        self.env = {
            "ROS_MASTER_URI": self.uri,
            "ROS_IP": "127.0.0.1",
            "ROS_HOME": str(home),
            "ROS_LOG_DIR": str(home / "log"),
            "ROS_PACKAGE_PATH": os.pathsep.join(package_path),
            "PYTHONPATH": os.pathsep.join(python_path),
            "PYTHONUNBUFFERED": "1",
        }
        self.env.pop("ROS_HOSTNAME", None)
        self.proc = subprocess.Popen(
            ["rosmaster", "--core", "-p", str(self.port)],
            env={**os.environ, **self.env}, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        self._wait_online(timeout=15.0)

    def _wait_online(self, timeout: float) -> None:
        import time
        import xmlrpc.client

        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"rosmaster exited with {self.proc.returncode}")
            try:
                code, _, _ = xmlrpc.client.ServerProxy(self.uri).getPid("/pytest")
                if code == 1:
                    return
            except OSError:
                pass
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"rosmaster on port {self.port} did not come up in {timeout} s")

    def stop(self) -> None:
        import subprocess

        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


@pytest.fixture(scope="module")
def ros_master(
    tmp_path_factory: pytest.TempPathFactory, woosh_msgs_build: Path
) -> Iterator[RosMaster]:
    """A private rosmaster for the module; its ``env`` finds woosh_msgs and lowerbase_driver."""
    import shutil

    require_ros((*ROS_MODULES, "rosgraph", "rosbag"))
    if shutil.which("rosmaster") is None:
        reason = "rosmaster is not on PATH; run scripts/install-ros.sh as root"
        if is_ci():
            pytest.fail(f"CI=true requires ROS: {reason}", pytrace=False)
        pytest.skip(reason)
    driver_package = Path(__file__).resolve().parents[2] / "lowerbase" / "driver"
    master = RosMaster(tmp_path_factory.mktemp("ros_home"),
                       share_dirs=[woosh_msgs_build / "share", driver_package],
                       python_dirs=[woosh_msgs_build])
    try:
        yield master
    finally:
        master.stop()
