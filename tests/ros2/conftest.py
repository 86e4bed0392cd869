"""ROS 2 tests: genuine rclpy processes of the ROS 2 venv (``make ros2``, docs/ros2.md).

``make test`` sets the venv up first where this machine can have it (``scripts/ros2-env.sh
--optional``); where it cannot, or before ``make ros2`` in a bare tree, they skip with one line
saying why. Every process they start keeps discovery on this machine
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and gets a ROS_DOMAIN_ID of its test's own.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from lowerbase.errors import ConfigError

HERE = Path(__file__).resolve().parent
_domains = itertools.count((os.getpid() % 40) * 5 + 20)  # 20..219, ROS 2's usable range


@dataclass
class Ros2:
    """Runs Python scripts in the ROS 2 venv with the built interfaces and a domain id."""

    python: Path
    env: dict[str, str]

    def popen(self, script: str, *args: str, **kw: Any) -> subprocess.Popen[str]:
        return subprocess.Popen([str(self.python), str(HERE / script), *args], env=self.env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)

    def run_json(self, script: str, *args: str, timeout: float = 60.0) -> Any:
        proc = subprocess.run([str(self.python), str(HERE / script), *args], env=self.env,
                              capture_output=True, text=True, timeout=timeout)
        assert proc.returncode == 0, f"{script} failed ({proc.returncode}):\n{proc.stderr}"
        return json.loads(proc.stdout.strip().splitlines()[-1])


def ros2_or_skip() -> Ros2:
    from lowerbase.cli.ros2_env import ros2_paths
    from lowerbase.ros2.interfaces import env_for

    if os.environ.get("LOWERBASE_WITHOUT_ROS", "").lower() in ("true", "1"):
        pytest.skip("LOWERBASE_WITHOUT_ROS=1 (make test-oldest): the ROS 2 processes are the "
                    "same as in make test, which runs them")
    try:
        venv, install = ros2_paths()
    except ConfigError as exc:
        pytest.skip(f"ROS 2 not set up: {exc}")
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the ROS 1 venv's paths have woosh_msgs of their own
    env.pop("ROS_PACKAGE_PATH", None)
    env.update(env_for(venv, install))
    env["ROS_DOMAIN_ID"] = str(next(_domains))
    return Ros2(venv / "bin" / "python", env)


@pytest.fixture
def ros2() -> Ros2:
    return ros2_or_skip()
