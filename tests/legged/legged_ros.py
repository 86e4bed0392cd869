"""ROS fixtures of the legged robot's tests: the generated message packages and a rosmaster.

Imported by the test modules that need them (``from tests.legged.legged_ros import ...``) rather
than from a conftest.py, so that tests/legged can hold other suites' conftest freely.
"""

from __future__ import annotations

import importlib
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from tests.driver.conftest import ROS_MODULES, RosMaster, is_ci, require_ros

LEGGED_PKG = "lowerbase_legged_msgs"
_HIDDEN = ("woosh_msgs", LEGGED_PKG)


def _generated(name: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in _HIDDEN)


@pytest.fixture(scope="module")
def legged_build(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Every msggen package generated into a fresh directory, first on ``sys.path``.

    Packages already importable (the venv's .pth to build/ros) are hidden meanwhile, so that
    the tests check what this checkout generates.
    """
    require_ros((*ROS_MODULES, "sensor_msgs.msg"))
    from lowerbase.driver import msggen

    out = tmp_path_factory.mktemp("legged_ros")
    for package in msggen.PACKAGES:
        msggen.generate(out, package=package)
    saved = {k: v for k, v in sys.modules.items() if _generated(k)}
    for k in saved:
        del sys.modules[k]
    sys.path.insert(0, str(out))
    importlib.invalidate_caches()
    try:
        yield out
    finally:
        sys.path.remove(str(out))
        for k in [k for k in sys.modules if _generated(k)]:
            del sys.modules[k]
        sys.modules.update(saved)


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
