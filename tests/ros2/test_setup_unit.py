"""The ROS-2-free parts of the setup: the ROS 1 translation, the cache key and
``lowerbase ros2-env`` (these run in the ROS 1 venv too)."""

from __future__ import annotations

import os
import socket
import subprocess
from pathlib import Path

import pytest

from lowerbase.cli import main
from lowerbase.ros2 import interfaces
from lowerbase.ros2.interfaces import definitions_hash, dependencies, translate_ros1


def test_translate_ros1_renames_header_time_duration_only() -> None:
    text = "Header header\ntime t # a time\nduration[] ds\nuint8 HeaderX\n# Header in a comment"
    assert translate_ros1(text).splitlines() == [
        "std_msgs/Header header", "builtin_interfaces/Time t # a time",
        "builtin_interfaces/Duration[] ds", "uint8 HeaderX", "# Header in a comment"]


def test_dependencies_are_the_named_packages() -> None:
    texts = ["std_msgs/Header header\ngeometry_msgs/PoseStamped[] p\nwoosh_msgs/X x\nuint8 a"]
    assert dependencies(texts, "woosh_msgs") == ["geometry_msgs", "std_msgs"]


def test_cache_key_is_stable_and_short() -> None:
    assert definitions_hash() == definitions_hash() and len(definitions_hash()) == 16


def test_ros2_env_says_what_to_do_without_make_ros2(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ros2-env", "--venv", str(tmp_path / "none")]) != 0
    err = capsys.readouterr().err
    assert "run make ros2" in err and len(err.strip().splitlines()) == 1


def test_ros2_env_prints_the_exports(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").touch()
    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / ".complete").touch()
    monkeypatch.setattr(interfaces, "cache_dir", lambda root=None: cache)
    assert main(["ros2-env", "--venv", str(venv)]) == 0
    out = capsys.readouterr().out
    assert f"export PATH={venv}/bin:\"$PATH\"" in out
    assert f"export AMENT_PREFIX_PATH={cache}/install:{venv}" in out
    assert f"export LD_LIBRARY_PATH={cache}/install/lib" in out
    assert "export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST" in out
    assert "PYTHONPATH" not in out


SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "ros2-env.sh"


def _optional(tmp_path: Path, **env: str) -> subprocess.CompletedProcess[str]:
    """``scripts/ros2-env.sh --optional`` (what ``make test`` runs) into a venv under tmp."""
    full = {k: v for k, v in os.environ.items() if not k.startswith("PIP_")}
    full.update(ROS2_VENV=str(tmp_path / "venv-ros2"), **env)
    return subprocess.run(["bash", str(SCRIPT), "--optional"], env=full, capture_output=True,
                          text=True, timeout=120)


def test_make_test_skips_ros2_in_one_line_when_told_to(tmp_path: Path) -> None:
    done = _optional(tmp_path, ROS2="0")
    assert done.returncode == 0
    assert done.stderr.strip().splitlines() == [
        "make test: ROS 2 not set up, tests/ros2 will skip: ROS2=0 (make ros2 sets it up on "
        "its own)"]
    assert not (tmp_path / "venv-ros2").exists()


def test_make_test_skips_ros2_in_one_line_without_the_registry(tmp_path: Path) -> None:
    with socket.socket() as closed:  # a loopback port that refuses: the index is unreachable
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
    done = _optional(tmp_path, PIP_INDEX_URL=f"http://127.0.0.1:{port}/simple")
    assert done.returncode == 0, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    # the machine may lack a prerequisite checked before the registry; else it is the registry
    assert lines[0].startswith("make test: ROS 2 not set up, tests/ros2 will skip: ")
    if "x86_64" not in lines[0] and "not found" not in lines[0] and "Python 3.11" not in lines[0]:
        assert f"127.0.0.1:{port}/simple/ros-rclpy/" in lines[0]
    assert not (tmp_path / "venv-ros2").exists()
