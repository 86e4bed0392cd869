"""ROS fixtures of the trace tests: every msggen package generated afresh, a rosmaster.

Imported by the test modules that need them (``from tests.trace.trace_ros import ...``), as
tests/legged_driver/legged_ros.py does; everything skips without ROS (tests/driver/conftest.py).
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

PKG = "lowerbase_msgs"
_HIDDEN = ("woosh_msgs", "lowerbase_legged_msgs", PKG)
DRIVER_PACKAGE = Path(__file__).resolve().parents[2] / "lowerbase" / "driver"


@pytest.fixture(scope="module")
def trace_build(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Every msggen package generated into a fresh directory, first on ``sys.path`` (the
    venv's build/ros hidden meanwhile: the tests check what this checkout generates)."""
    require_ros((*ROS_MODULES, "sensor_msgs.msg"))
    with every_msggen_package(tmp_path_factory.mktemp("traceros_build"), _HIDDEN) as path:
        yield path


@pytest.fixture(scope="module")
def lowerbase_msgs(trace_build: Path) -> ModuleType:
    module = importlib.import_module(f"{PKG}.msg")
    assert Path(module.__file__ or "").is_relative_to(trace_build), module.__file__
    return module


@pytest.fixture(scope="module")
def trace_master(tmp_path_factory: pytest.TempPathFactory, trace_build: Path
                 ) -> Iterator[RosMaster]:
    """A private rosmaster whose ``env`` finds the generated packages and lowerbase_driver."""
    require_ros((*ROS_MODULES, "rosgraph", "rosbag", "tf2_ros"))
    if shutil.which("rosmaster") is None:
        reason = "rosmaster is not on PATH; run scripts/install-ros.sh as root"
        if is_ci():
            pytest.fail(f"CI=true requires ROS: {reason}", pytrace=False)
        pytest.skip(reason)
    master = RosMaster(tmp_path_factory.mktemp("traceros_home"),
                       share_dirs=[trace_build / "share", DRIVER_PACKAGE],
                       python_dirs=[trace_build])
    try:
        yield master
    finally:
        master.stop()
