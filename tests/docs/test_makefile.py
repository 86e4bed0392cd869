"""The Makefile's promises: `make bench` leaves the tracked docs alone unless asked."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from tests.conftest import ROOT

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs GNU make")


def _dry_run(*args: str) -> list[str]:
    """The commands `make -n` would run (nothing is executed)."""
    out = subprocess.run(["make", "-n", "--no-print-directory", *args], cwd=ROOT,
                         capture_output=True, text=True, check=True, timeout=30).stdout
    return out.splitlines()


def _bench_line(*args: str) -> str:
    lines = [line for line in _dry_run("bench", *args) if "-m benchmarks" in line]
    assert len(lines) == 1, lines
    return lines[0]


def test_make_bench_prints_only_by_default() -> None:
    assert "--write" not in _bench_line()


def test_make_bench_write_1_writes_the_docs() -> None:
    assert "--write docs/benchmarks.md" in _bench_line("WRITE=1")


def test_make_test_oldest_uses_python_3_10_without_system_site_packages() -> None:
    lines = _dry_run("test-oldest", "OLDEST_PYTHON=/opt/py310/bin/python3.10",
                     "OLDEST_VENV=build/venv-oldest-dry-run")
    venv = [line for line in lines if " -m venv " in line]
    assert venv and venv[0].startswith("/opt/py310/bin/python3.10 -m venv")
    assert "--system-site-packages" not in venv[0]
    assert any("build/venv-oldest-dry-run/bin/python -m pytest" in line for line in lines)


def test_make_test_oldest_without_python_3_10_fails_with_one_clear_line() -> None:
    proc = subprocess.run(["make", "--no-print-directory", "test-oldest", "OLDEST_PYTHON=",
                           "OLDEST_VENV=build/venv-oldest-missing"], cwd=ROOT,
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode != 0
    assert "no Python 3.10 found" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_make_ros2_builds_its_own_venv_and_make_test_only_where_it_can() -> None:
    ros2 = [line for line in _dry_run("ros2", "ROS2_VENV=build/x") if "ros2-env.sh" in line]
    assert ros2 == ["ROS2_VENV=build/x bash scripts/ros2-env.sh"]
    test = [line for line in _dry_run("-W", "pyproject.toml", "test") if "ros2-env.sh" in line]
    assert test == ["ROS2_VENV=.venv-ros2 bash scripts/ros2-env.sh --optional"]
