"""/odom over ROS 2: ``lowerbase driver --ros2`` publishing, an rclpy subscriber in another
process (``python -m lowerbase.ros2.latency``), both in the ROS 2 venv (``make ros2``).

Three processes on this host: ``lowerbase emulate`` on a udp_multicast port of its own, the
driver against it (/odom on every 50 Hz WheelFeedback), and the subscriber. Latency is the
subscriber's callback time minus the DDS source timestamp of the driver's ``publish``; lost is
the publication sequence numbers the subscriber never saw. Discovery stays on loopback, on
ROS_DOMAIN_ID :data:`DOMAIN`. Without ``make ros2`` the module returns no rows (one line on
stderr says why).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from typing import Any

from benchmarks.common import Row
from lowerbase.errors import ConfigError
from lowerbase.transport import free_loopback_port

GROUP = "239.74.163.99"
DOMAIN = 43
START_TIMEOUT = 300.0  # a cold numba cache compiles the EKF's kernels at the driver's start


def _ros2_env() -> tuple[str, dict[str, str]] | None:
    from lowerbase.cli.ros2_env import ros2_paths
    from lowerbase.ros2.interfaces import env_for

    try:
        venv, install = ros2_paths()
    except ConfigError as exc:
        print(f"# bench_ros2: skipped (ROS 2 not set up: {exc})", file=sys.stderr)
        return None
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    env.pop("ROS_PACKAGE_PATH", None)
    env.update(env_for(venv, install))
    env["ROS_DOMAIN_ID"] = str(DOMAIN)
    env["PYTHONUNBUFFERED"] = "1"
    return str(venv / "bin" / "python"), env


def _wait_line(proc: subprocess.Popen[str], wanted: str, timeout: float) -> str:
    assert proc.stdout is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        if wanted in line:
            return line
    raise RuntimeError(f"{proc.args!r} did not print {wanted!r} within {timeout:.0f} s")


def trial(seconds: float) -> dict[str, Any] | None:
    found = _ros2_env()
    if found is None:
        return None
    python, env = found
    bus = ["-i", "udp_multicast", "-c", GROUP, "--bus-kwargs",
           f"port={free_loopback_port()}", "hop_limit=0"]
    procs: list[subprocess.Popen[str]] = []

    def start(cmd: list[str], environ: dict[str, str]) -> subprocess.Popen[str]:
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                             stdin=subprocess.DEVNULL, text=True, env=environ)
        procs.append(p)
        return p

    try:
        emulator = start([sys.executable, "-m", "lowerbase", "emulate", *bus],
                         {**os.environ, "PYTHONUNBUFFERED": "1"})
        _wait_line(emulator, "lower computer on", 60.0)
        driver = start([python, "-m", "lowerbase", "driver", "--ros2", *bus], env)
        _wait_line(driver, "on ROS 2", START_TIMEOUT)
        probe = subprocess.run([python, "-m", "lowerbase.ros2.latency", "/odom", str(seconds)],
                               env=env, capture_output=True, text=True,
                               timeout=seconds + 180.0)
        if probe.returncode != 0:
            raise RuntimeError(f"lowerbase.ros2.latency failed: {probe.stderr.strip()}")
        result: dict[str, Any] = json.loads(probe.stdout.strip().splitlines()[-1])
        result["load"] = os.getloadavg()[0]
        return result
    finally:
        for p in reversed(procs):
            p.send_signal(2)
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def run(quick: bool = False) -> list[Row]:
    seconds = 5.0 if quick else 30.0
    got = trial(seconds)
    if got is None:
        return []
    g = "ros2"
    return [
        Row(g, "/odom publish -> rclpy subscriber p99", got["p99_ms"], "ms",
            f"target <= 5 ms idle; p50 {got['p50_ms']:.2f}, max {got['max_ms']:.2f} ms "
            f"(at {got['worst_at_s']:.1f} s), {got['over_10ms']} over 10 ms; "
            f"{got['count']} messages in {seconds:g} s ({got['rate']:.1f} Hz), "
            f"Fast DDS on loopback, reliable QoS; load {got['load']:.1f}"),
        Row(g, "/odom messages lost, driver -> rclpy subscriber", got["lost"], "messages",
            f"target 0; publication sequence numbers skipped over {got['count']} received"),
    ]


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        print(row)
