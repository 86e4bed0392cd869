"""Every `lowerbase ...` command shown in README.md and docs/*.md runs here, so examples cannot
rot (the mbpoll commands of docs/bms-modbus.md are tested in tests/bms).

Commands are extracted from the fenced code blocks; each one needs an entry in CHECKS, which
says how it is run: ``run`` to the end (exit 0), ``start`` (wait for its ready line, then
Ctrl-C: servers and real-time runs), or ``skip`` with the reason (SocketCAN, roscore, hardware).
A command is run as documented, in a scratch directory, on a bus of its own (python-can's
CAN_INTERFACE/CAN_CHANNEL/CAN_CONFIG variables, which lowerbase honours); the only changes are
the ``replace`` pairs of its entry (fixed ports and paths made free ones, long durations
bounded, 0.0.0.0 made loopback), each with its reason.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.conftest import ROOT, TEST_GROUP, free_tcp_port, free_udp_port

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)


def documented_commands() -> dict[str, str]:
    """{command: where} for every `lowerbase ...` line of a fenced block (comments, a
    leading ``$ ``, a trailing ``&`` and anything piped into it removed)."""
    found: dict[str, str] = {}
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for block in _FENCE.finditer(text):
            first = text[: block.start()].count("\n") + 1
            for i, line in enumerate(block[1].splitlines(), first + 1):
                code = line.split(" #", 1)[0].strip().removeprefix("$ ").rstrip("&").strip()
                code = code.rsplit("|", 1)[-1].strip()  # candump vcan0 | lowerbase decode
                # `lowerbase` then a subcommand or an option (not prose: "lowerbase emulate: ...")
                if re.match(r"lowerbase(\s+(-|[a-z]+(\s|$))|$)", code):
                    found.setdefault(" ".join(code.split()), f"{doc.relative_to(ROOT)}:{i}")
    return found


@dataclass(frozen=True)
class Check:
    how: str  #: "run", "start" or "skip"
    expect: str = ""  #: text the output must contain (for "start": the ready line)
    replace: tuple[tuple[str, str], ...] = ()  #: (documented, run) text; {tcp} = a free port
    why: str = ""  #: the reason for a skip or for the replacements
    stdin: str = ""
    peer: bool = False  #: run against `lowerbase emulate` on the same bus
    files: tuple[str, ...] = ()  #: files the run must leave in its directory
    #: [s] a "run" that has not ended by then hangs (a bound, not a speed: CI hosts are busy;
    #: beside 12 busy processes a simulated scenario of 10 s CPU took over 60 s)
    timeout: float = 300.0


FREE_TCP = (("127.0.0.1:5020", "127.0.0.1:{tcp}"),)
BMS_TCP = "a free loopback port instead of the default 5020, which other runs may hold"
SOCKETCAN = "needs SocketCAN (can0) with real firmware on it"
ROS = "needs rospy and a roscore"

CHECKS: dict[str, Check] = {
    "lowerbase --help": Check("run", "commands"),
    "lowerbase emulate": Check("start", "Ctrl-C stops"),
    "lowerbase driver": Check("skip", why=ROS),
    "lowerbase driver --replay run.blf": Check("skip", why=ROS),
    "lowerbase emulate --map warehouse --truth-udp": Check("start", "Ctrl-C stops"),
    "lowerbase world --map warehouse": Check("skip", why=ROS),
    "lowerbase world --map empty_room --ground-truth --no-camera": Check("skip", why=ROS),
    "lowerbase navigation --map warehouse": Check("skip", why=ROS),
    "lowerbase trace --map warehouse": Check("skip", why=ROS),
    "lowerbase tasks --map warehouse": Check("skip", why=ROS),
    "lowerbase robot --map warehouse": Check("skip", why=ROS),
    "lowerbase robot --map empty_room --without navigation --without tasks": Check(
        "skip", why=ROS),
    # tests/robot/test_robot_whole_ros.py and test_robot_lockstep_ros.py run these on a master
    "lowerbase robot --map warehouse --sim-time --speed max": Check("skip", why=ROS),
    "lowerbase robot --robot legged --sim-time": Check("skip", why=ROS),
    "lowerbase robot --map warehouse --sim-time --paused --speed max": Check("skip", why=ROS),
    "lowerbase robot --map warehouse --sim-time --paused --speed max --seed 2": Check(
        "skip", why=ROS),
    "lowerbase robot --map warehouse --sim-time --paused --speed max --truth /tmp/truth.csv":
        Check("skip", why=ROS),
    "lowerbase robot --map warehouse --mcap robot.mcap": Check("skip", why=ROS),
    "lowerbase robot --map warehouse --foxglove": Check("skip", why=ROS),
    # tests/robot/test_robot_charging_ros.py runs it (with --sim-time --speed 2) on its master
    "lowerbase robot --map empty_room --soc 30 --ground-truth": Check("skip", why=ROS),
    "lowerbase emulate --fleet 100": Check("start", "Ctrl-C stops"),
    "lowerbase driver --bus-kwargs port=43115": Check("skip", why=ROS),
    "lowerbase driver --robot legged": Check("skip", why=ROS),
    "lowerbase emulate --robot legged": Check("start", "Ctrl-C stops"),
    "lowerbase emulate --robot legged --simulated --duration 10": Check(
        "run", "stopped after 10.0 s"),
    "lowerbase driver --robot legged _mapping_plugin:=false '_gps_origin:=[31.2,121.5,4.0]'":
        Check("skip", why=ROS),
    "lowerbase emulate --fault stall:left@10+2": Check("start", "Ctrl-C stops"),
    "lowerbase emulate --serial pty:/tmp/chassis-tty": Check(
        "start", "chassis-tty", (("/tmp/chassis-tty", "{dir}/chassis-tty"),),
        why="a pty link of this run's own"),
    "lowerbase emulate --slcan pty:/tmp/chassis-slcan": Check(
        "start", "chassis-slcan", (("/tmp/chassis-slcan", "{dir}/chassis-slcan"),),
        why="a pty link of this run's own"),
    "lowerbase bms --tcp 127.0.0.1:5020": Check("start", "listening on 127.0.0.1:", FREE_TCP,
                                                why=BMS_TCP),
    "lowerbase bms": Check("start", "listening on 127.0.0.1:",
                           (("lowerbase bms", "lowerbase bms --tcp 127.0.0.1:{tcp}"),),
                           why=BMS_TCP),
    "lowerbase bms --tcp 0.0.0.0:1502 --unit 3": Check(
        "start", "unit 3", (("0.0.0.0:1502", "127.0.0.1:{tcp}"),),
        why="tests bind loopback only"),
    "lowerbase bms --idle-timeout 300": Check(
        "start", "listening on 127.0.0.1:", (("--idle-timeout", "--tcp 127.0.0.1:{tcp} "
                                              "--idle-timeout"),), why=BMS_TCP),
    "lowerbase bms --rtu /dev/ttyUSB0 --no-tcp": Check("skip", why="needs a USB-RS485 adapter"),
    "lowerbase bms --rtu pty:/tmp/lowerbase-bms": Check(
        "start", "lowerbase-bms", (("pty:/tmp/lowerbase-bms",
                                    "pty:{dir}/lowerbase-bms --tcp 127.0.0.1:{tcp}"),),
        why="a pty link of this run's own; " + BMS_TCP),
    "lowerbase bms --profile robot.toml --soc 25 --charger --speed 60": Check(
        "start", "SOC 25", (("--speed 60", "--speed 60 --tcp 127.0.0.1:{tcp}"),),
        why="robot.toml: a copy of the default profile; " + BMS_TCP),
    "lowerbase conformance": Check("start", " PASS ", peer=True,
                                   why="stopped after its first check result"),
    "lowerbase conformance -i socketcan -c can0": Check("skip", why=SOCKETCAN),
    "lowerbase conformance -i pcan -c PCAN_USBBUS1 -b 500000": Check(
        "skip", why="needs a PEAK PCAN-USB adapter"),
    "lowerbase conformance --serial /dev/ttyUSB0": Check(
        "skip", why="needs firmware on a serial port"),
    "lowerbase conformance --junit conformance.xml": Check(
        "run", "JUnit XML written", (("--junit", "--only frame.Heartbeat.* --junit"),),
        why="bounded to the Heartbeat checks", peer=True, files=("conformance.xml",)),
    "lowerbase conformance --only 'frame.Heartbeat.*,safety.*'": Check(
        "start", "frame.Heartbeat.", peer=True, why="stopped after its first check result"),
    "lowerbase conformance --list": Check("run", "frame.Heartbeat"),
    "lowerbase conformance --robot legged -i socketcan -c can0,can1,can2,can3": Check(
        "skip", why=SOCKETCAN),
    "lowerbase conformance --robot legged --list": Check("run", "actuator.test_mode"),
    "lowerbase scenario run scenarios/watchdog.toml": Check(
        "run", "scenario watchdog: PASSED", (("scenarios/", f"{ROOT}/scenarios/"),),
        why="run in a scratch directory (the report goes to ./reports)"),
    "lowerbase scenario list": Check("run", "watchdog"),
    "lowerbase scenario run watchdog": Check("run", "scenario watchdog: PASSED"),
    "lowerbase scenario run legged_stand_walk_sit": Check(
        "run", "scenario legged_stand_walk_sit: PASSED"),
    "lowerbase scenario run my.toml --out rep/": Check("run", "PASSED",
                                                       files=("rep/index.html",)),
    "lowerbase scenario run estop --realtime": Check("start", "realtime"),
    "lowerbase scenario run demo --processes": Check("start", "processes"),
    "lowerbase scenario run loop --record run.blf": Check(
        "run", "PASSED", (("run.blf", "loop.blf"),), files=("loop.blf",),
        why="a file name of its own: run.blf is the prepared recording"),
    "lowerbase scenario check my.toml": Check("run", "my.toml"),
    "lowerbase scenario replay run.blf": Check("run", "report:"),
    "lowerbase record run.blf --duration 60": Check(
        "run", "written to run.blf", (("--duration 60", "--duration 1"),), peer=True,
        why="bounded to 1 s"),
    "lowerbase record bus.log --duration 10": Check(
        "run", "written to bus.log", (("--duration 10", "--duration 1"),), peer=True,
        why="bounded to 1 s"),
    "lowerbase scenario run watchdog --mcap watchdog.mcap": Check(
        "run", "mcap: watchdog.mcap", files=("watchdog.mcap",)),
    "lowerbase scenario run tasks/transport --mcap transport.mcap": Check(
        "run", "mcap: transport.mcap", files=("transport.mcap",)),
    "lowerbase mcap info prep/run.mcap": Check("run", "/ground_truth/odom"),
    "lowerbase mcap to-bag prep/run.mcap run.bag": Check("run", "-> run.bag",
                                                          files=("run.bag",)),
    "lowerbase mcap from-bag run.bag back.mcap": Check("run", "-> back.mcap",
                                                        files=("back.mcap",)),
    "lowerbase mcap recover prep/run.mcap whole.mcap": Check("run", "the file was whole",
                                                             files=("whole.mcap",)),
    "lowerbase scenario run watchdog --realtime --foxglove": Check(
        "start", "live view: Foxglove", (("--foxglove", "--foxglove 127.0.0.1:{tcp}"),),
        why="a free port for 8765"),
    "lowerbase emulate --foxglove": Check(
        "start", "live view: Foxglove", (("--foxglove", "--foxglove 127.0.0.1:{tcp}"),),
        why="a free port for 8765"),
    "lowerbase record run.mcap --duration 10": Check(
        "run", "written to run.mcap", (("--duration 10", "--duration 1"),), peer=True,
        why="bounded to 1 s"),
    "lowerbase decode": Check("run", "Heartbeat", why="candump's lines given on stdin",
                              stdin="(1.0) vcan0 090#D430000003000101\n"),
    "lowerbase dbc --signals": Check("run", "WheelFeedback"),
    "lowerbase demo": Check("start", "lowerbase demo:"),
    "lowerbase demo --chassis": Check("start", "lowerbase demo:"),
    "lowerbase scenario run tasks/transport": Check("run", "scenario tasks_transport: PASSED"),
    "lowerbase campaign run campaigns/wheel_tolerance.toml": Check(
        "run", "campaign wheel_tolerance: ", (("campaigns/wheel_tolerance.toml",
                                               f"{ROOT}/campaigns/wheel_tolerance.toml "
                                               "--runs 0-5 --workers 2"),),
        why="the repository's campaign from the scratch directory; 6 of its 100 runs on "
        "two workers (the same path, a tenth of the time)", timeout=600.0),
    "lowerbase campaign replay campaigns/wheel_tolerance.toml --run 0": Check(
        "run", "scenario loop: PASSED", (("campaigns/", f"{ROOT}/campaigns/"),),
        why="the repository's campaign from the scratch directory", timeout=300.0),
    "lowerbase campaign check campaigns/wheel_tolerance.toml": Check(
        "run", "ok (100 runs", (("campaigns/", f"{ROOT}/campaigns/"),),
        why="the repository's campaign from the scratch directory"),
    "lowerbase campaign run campaigns/wheel_tolerance.toml --scheduler tcp://10.0.0.5:8786":
        Check("skip", why="needs a Dask cluster at 10.0.0.5 (tests/campaign/test_cluster.py "
              "runs one on 127.0.0.1)"),
}

MY_SCENARIO = """[scenario]
name = "mine"
duration = 3.0

[[timeline]]
at = 0.5
action = "twist"
linear = 0.3
duration = 1.0

[[expect]]
kind = "stopped"
after = 2.0
within = 0.6
"""


def test_every_documented_command_has_a_check() -> None:
    documented = documented_commands()
    missing = {cmd: where for cmd, where in documented.items() if cmd not in CHECKS}
    assert not missing, f"documented commands no test runs (add them to CHECKS): {missing}"
    stale = set(CHECKS) - set(documented)
    assert not stale, f"CHECKS for commands no longer documented: {stale}"


def test_the_extraction_finds_the_everyday_commands() -> None:
    documented = documented_commands()
    assert "lowerbase emulate --fault stall:left@10+2" in documented
    assert "lowerbase decode" in documented  # piped: candump vcan0 | lowerbase decode
    assert "lowerbase emulate" in documented  # driver.md: `lowerbase emulate &`


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Files the documented commands name: my.toml, robot.toml, run.blf, prep/run.mcap,
    run.bag."""
    d = tmp_path_factory.mktemp("doc-commands")
    (d / "my.toml").write_text(MY_SCENARIO, encoding="utf-8")
    shutil.copy(ROOT / "lowerbase" / "profiles" / "default.toml", d / "robot.toml")
    subprocess.run([sys.executable, "-m", "lowerbase", "scenario", "run", "my.toml",
                    "--record", "run.blf", "--out", "prep"], cwd=d, check=True,
                   capture_output=True, timeout=60)
    subprocess.run([sys.executable, "-m", "lowerbase", "mcap", "to-bag", "prep/run.mcap",
                    "run.bag"], cwd=d, check=True, capture_output=True, timeout=60)
    return d


class Running:
    """A command's process, stdout and stderr merged and read line by line."""

    def __init__(self, argv: list[str], cwd: Path, env: dict[str, str], stdin: str) -> None:
        self.popen = subprocess.Popen(argv, cwd=cwd, env=env, text=True,
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT)
        assert self.popen.stdin is not None
        self.popen.stdin.write(stdin)
        self.popen.stdin.close()
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self._queue.put(line)
        self._queue.put(None)

    def wait_for(self, text: str, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self._queue.get(timeout=left)
            except queue.Empty:
                return False
            if line is None:
                return False
            self.lines.append(line)
            if text in line:
                return True
        return False

    def finish(self, timeout: float) -> int:
        """Exit code after the process ends (killed after ``timeout``)."""
        try:
            self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait()
        while (line := self._queue.get(timeout=5)) is not None:
            self.lines.append(line)
        return self.popen.returncode

    def stop(self) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGINT)
        return self.finish(60)  # a bound: a busy host stops slowly

    @property
    def output(self) -> str:
        return "".join(self.lines)


@pytest.fixture
def bus_env() -> Iterator[dict[str, str]]:
    """A udp_multicast bus of this test's own, through python-can's variables."""
    config = {"port": free_udp_port(), "hop_limit": 0}
    yield {**os.environ, "CAN_INTERFACE": "udp_multicast", "CAN_CHANNEL": TEST_GROUP,
           "CAN_CONFIG": json.dumps(config), "PYTHONUNBUFFERED": "1"}


@pytest.mark.process
@pytest.mark.parametrize("command", sorted(CHECKS))
def test_documented_command(command: str, workdir: Path, bus_env: dict[str, str],
                            tmp_path: Path) -> None:
    check = CHECKS[command]
    if check.how == "skip":
        pytest.skip(check.why)
    line = command
    for documented, used in check.replace:
        assert documented in line, f"stale replacement {documented!r} for {command!r}"
        line = line.replace(documented, used)
    line = line.format(tcp=free_tcp_port(), dir=tmp_path)
    run_dir = tmp_path / "run"
    shutil.copytree(workdir, run_dir)
    argv = [sys.executable, "-m", "lowerbase", *shlex.split(line)[1:]]
    peer = Running([sys.executable, "-m", "lowerbase", "emulate"], run_dir, bus_env, "") \
        if check.peer else None
    try:
        if peer is not None:
            assert peer.wait_for("Ctrl-C stops", 90), peer.output
        proc = Running(argv, run_dir, bus_env, check.stdin)
        if check.how == "start":
            ready = proc.wait_for(check.expect, 90)
            code = proc.stop()
            assert ready, f"{line!r} did not print {check.expect!r}: {proc.output}"
            # Ctrl-C: a clean stop. Exit 130 and death by SIGINT (-2) are what a shell shows
            # alike ($? = 130); what must never appear is a traceback.
            assert code in (0, 130, -signal.SIGINT), proc.output
            assert "Traceback" not in proc.output, proc.output
        else:
            code = proc.finish(check.timeout)
            assert code == 0, f"{line!r} exited {code}: {proc.output}"
            assert check.expect in proc.output, proc.output
    finally:
        if peer is not None:
            peer.stop()
    assert "Traceback" not in proc.output, proc.output
    for name in check.files:
        assert (run_dir / name).exists(), f"{line!r} did not write {name}"
