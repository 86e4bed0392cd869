"""The supervisor of ``lowerbase robot`` on small stand-in children (python one-liners): start
order, readiness, a part ending, Ctrl-C and a part that ignores it."""

from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path
from typing import Any

import pytest

from lowerbase.robot.supervisor import ChildSpec, RobotError, Supervisor


def script(body: str, name: str = "part", ready: str | None = "ready",
           timeout: float = 20.0) -> ChildSpec:
    return ChildSpec(name, [sys.executable, "-u", "-c", body], ready, timeout)


# the marker is written (and closed) before the ready line: once a part is seen ready, its
# line is in the file (written after it, it raced the test's read under load)
SERVE = ("import time\nprint('booting')\n"
         "with open('{marker}', 'a') as f: f.write('{name}\\n')\n"
         "print('{name} ready', flush=True)\n"
         "time.sleep(600)\n")


def serving(name: str, marker: Path) -> ChildSpec:
    return script(SERVE.format(name=name, marker=marker), name)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_children_start_in_order_each_once_ready_and_stop_in_reverse(tmp_path: Path) -> None:
    marker = tmp_path / "order"
    sup = Supervisor(tmp_path / "logs")
    seen: list[str] = []
    try:
        sup.start([serving("a", marker), serving("b", marker), serving("c", marker)],
                  on_ready=lambda child: seen.append(child.spec.name))
        assert seen == ["a", "b", "c"]
        assert all(c.ready and c.poll() is None for c in sup.children)
        # each was ready (had printed) before the next one was started
        assert marker.read_text().split() == ["a", "b", "c"]
    finally:
        codes = sup.stop_all()
    assert list(codes) == ["c", "b", "a"]
    assert not any(alive(c.popen.pid) for c in sup.children)
    log = (tmp_path / "logs" / "b.log").read_text()
    assert "booting" in log and "b ready" in log


def test_a_part_that_ends_while_starting_is_named_with_its_last_line_and_log(
        tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    with pytest.raises(RobotError) as err:
        sup.start([script("print('no map called nowhere; try --map warehouse'); "
                          "raise SystemExit(1)", "world")])
    sup.stop_all()
    text = str(err.value)
    assert "world ended while starting (exit code 1)" in text
    assert "no map called nowhere" in text and str(tmp_path / "world.log") in text
    assert "\n" not in text


def test_a_silent_part_times_out(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    with pytest.raises(RobotError, match=r"quiet not ready after 0\.5 s"):
        sup.start([script("import time; time.sleep(600)", "quiet", timeout=0.5)])
    sup.stop_all()
    assert sup.children[0].poll() is not None


def test_watch_returns_the_part_that_ended_and_the_others_are_stopped(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    sup.start([serving("keeps", tmp_path / "m"),
               script("print('ready', flush=True); import time; time.sleep(0.3); "
                      "print('lost the bus'); raise SystemExit(3)", "dies")])
    ended = sup.watch(every=0.05)
    codes = sup.stop_all()
    assert ended is not None and ended.spec.name == "dies"
    assert codes["dies"] == 3 and ended.last_line == "lost the bus"
    assert codes["keeps"] != 0 and sup.children[0].poll() is not None


def test_request_stop_ends_watch_and_a_part_ignoring_ctrl_c_is_killed(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    stubborn = ("import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
                "print('ready', flush=True); time.sleep(600)")
    sup.start([script(stubborn, "stubborn")])
    sup.request_stop()
    assert sup.watch(every=0.05) is None
    assert sup.children[0].stop(grace=0.5) == -9


def test_a_command_that_does_not_exist_is_one_line(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    with pytest.raises(RobotError, match="ghost: cannot start /no/such/binary"):
        sup.start([ChildSpec("ghost", ["/no/such/binary"])])


SUPERVISE = '''
import sys, time
from pathlib import Path
from typing import Any
from lowerbase.robot.supervisor import ChildSpec, Supervisor
sup = Supervisor(Path(sys.argv[1]))
sup.start([ChildSpec("part", [sys.executable, "-u", "-c",
                              "import os, time\\nprint('ready', os.getpid(), flush=True)\\n"
                              "time.sleep(600)"], "ready", 30.0)])
print("child", sup.children[0].popen.pid, flush=True)
time.sleep(600)
'''


def _gone(pid: int) -> bool:
    """No such process, or a zombie (dead, not yet reaped by whoever adopted it)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return True
    return "\nState:\tZ" in status


@pytest.mark.process
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl is Linux's")
def test_parts_die_with_a_supervisor_killed_by_sigkill(tmp_path: Path) -> None:
    """kill -9 of ``lowerbase robot`` left every part running (issue 22, item 7): each part
    gets SIGTERM when its supervisor dies, however it dies."""
    import signal
    import subprocess
    import time

    from tests.conftest import ROOT

    sup = subprocess.Popen([sys.executable, "-u", "-c", SUPERVISE, str(tmp_path)],
                           stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert sup.stdout is not None
        line = sup.stdout.readline()
        assert line.startswith("child "), line
        child = int(line.split()[1])
        assert not _gone(child)
    finally:
        sup.send_signal(signal.SIGKILL)
        sup.wait()
    deadline = time.monotonic() + 30.0
    while not _gone(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    if not _gone(child):
        os.kill(child, signal.SIGKILL)
        raise AssertionError("the part outlived its supervisor")


def test_the_guard_refuses_to_start_once_its_parent_is_gone(tmp_path: Path) -> None:
    import subprocess

    marker = tmp_path / "started"
    guard = [sys.executable, "-m", "lowerbase.robot.guard"]
    run = subprocess.run([*guard, str(2 ** 22 + 7), "touch", str(marker)], timeout=60)
    assert run.returncode == 1 and not marker.exists()  # not its parent: nothing started
    run = subprocess.run([*guard, str(os.getpid()), "touch", str(marker)], timeout=60)
    assert run.returncode == 0 and marker.exists()
    assert subprocess.run([*guard, "x"], capture_output=True, timeout=60).returncode == 2


def test_a_part_the_robot_goes_on_without_is_reported_once_and_the_watch_goes_on(
        tmp_path: Path) -> None:
    """Issue 22, item 9: the recorder's death ended the robot run."""
    from dataclasses import replace

    sup = Supervisor(tmp_path)
    recorder = replace(script("print('ready', flush=True); import time; time.sleep(0.2); "
                              "print('disk full'); raise SystemExit(2)", "recorder"),
                       essential=False)
    sup.start([serving("keeps", tmp_path / "m"), recorder,
               script("print('ready', flush=True); import time; time.sleep(1.5); "
                      "raise SystemExit(4)", "dies")])
    lost: list[str] = []
    ended = sup.watch(every=0.05, on_lost=lambda c: lost.append(f"{c.spec.name} "
                                                               f"{c.last_line}"))
    sup.stop_all()
    assert lost == ["recorder disk full"]
    assert ended is not None and ended.spec.name == "dies"


def test_a_crash_is_quoted_by_its_own_last_lines(tmp_path: Path) -> None:
    """Issue 22 item 8: the end names the crash's traceback, not the last line the part
    printed before it (a stale warning)."""
    sup = Supervisor(tmp_path)
    sup.start([script("print('ready', flush=True); print('warning: something stale'); "
                      "import time; time.sleep(0.2); raise RuntimeError('navigation broke')",
                      "crashes")])
    downs: list[Any] = []
    ended = sup.watch(every=0.05, on_down=downs.append)
    sup.stop_all()
    assert ended is not None and downs == [ended]  # told before the run ends
    tail = ended.tail(3)
    assert tail[-1] == "RuntimeError: navigation broke"
    assert all("stale" not in line for line in tail)


def test_a_part_to_respawn_is_started_again_and_the_others_go_on(tmp_path: Path) -> None:
    """``lowerbase robot --respawn`` (issue 22 item 8): the upper part that crashes is started
    again (its log goes on), the run does not end."""
    sup = Supervisor(tmp_path)
    marker = tmp_path / "crashed-once"
    crash_once = (f"import pathlib, time; m = pathlib.Path({str(marker)!r}); "
                  "print('ready', flush=True); time.sleep(0.2)\n"
                  "if not m.exists():\n    m.touch(); raise RuntimeError('navigation broke')\n"
                  "time.sleep(600)")
    sup.start([serving("keeps", tmp_path / "m")])
    spec = script(crash_once, "nav")
    sup.start([dataclasses.replace(spec, respawn=True)])
    seen: list[tuple[int, list[str]]] = []

    def respawned(old: Any, new: Any) -> None:
        seen.append((new.respawns, (old.final_lines or [])[-1:]))
        sup.request_stop()

    downs: list[tuple[str, bool]] = []

    def down(child: Any) -> None:  # before the respawn, the others still running
        downs.append((child.spec.name, sup.children[0].poll() is None))

    assert sup.watch(every=0.05, on_respawn=respawned, on_down=down) is None
    assert seen == [(1, ["RuntimeError: navigation broke"])] and downs == [("nav", True)]
    nav = sup.children[1]
    assert nav.poll() is None and nav.ready  # running again
    sup.stop_all()
    log = nav.log_path.read_text()
    assert "navigation broke" in log and log.count("ready") == 2  # one log, both runs
