"""Child processes of ``lowerbase robot``: started in order, each awaited until it says it is
ready, watched, and stopped in reverse order on every way out.

A :class:`Child` runs one command in a session of its own (so a Ctrl-C on the terminal reaches
only the supervisor, which then stops the children in order), with stdout and stderr merged
into a log file of its own. A reader thread copies the output to the log and notes the first
line that contains the child's ready text. :class:`Supervisor` starts the children one after
the other (a child that ends or stays silent past its start timeout is an error naming it and
its log), then watches them: one child ending ends the run, and every other child is stopped
(SIGINT, then SIGKILL after a grace period), unless it is to be respawned (``--respawn``: the
upper parts, started again as roslaunch's respawn does) or is not essential (the recorder).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from lowerbase.errors import LowerbaseError

STOP_GRACE = 8.0  #: [s] after SIGINT before a child is killed
RESPAWN_DELAY = 1.0  #: [s] after a respawned part ended before it starts again


class RobotError(LowerbaseError):
    """A part of the virtual robot did not start or ended."""


@dataclass(frozen=True)
class ChildSpec:
    """One process of the robot: ``argv`` (the full command), the text its output shows once
    it is ready (None: ready once started), and how long it may take [s]."""

    name: str
    argv: Sequence[str]
    ready_text: str | None = None
    start_timeout: float = 60.0
    env: dict[str, str] = field(default_factory=dict)
    #: False: the robot goes on without it when it ends after its start (the recorder)
    essential: bool = True
    #: started again when it ends after its start (roslaunch's respawn), after RESPAWN_DELAY
    respawn: bool = False


def guarded(argv: Sequence[str]) -> list[str]:
    """``argv`` run through :mod:`lowerbase.robot.guard`: it dies with this process."""
    import sys

    return [sys.executable, "-m", "lowerbase.robot.guard", str(os.getpid()), *argv]


class Child:
    """A running :class:`ChildSpec`, its output copied to ``log_path``."""

    def __init__(self, spec: ChildSpec, log_path: Path, *, append: bool = False) -> None:
        self.spec = spec
        self.log_path = log_path
        self._ready = threading.Event()
        self._ended = threading.Event()
        self.last_line = ""
        self.respawns = 0  #: times this part was started again (ChildSpec.respawn)
        #: the log's last lines when it was stopped (a respawned part's log goes on)
        self.final_lines: list[str] | None = None
        log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log: IO[str] = open(log_path, "a" if append else "w",  # noqa: SIM115
                                  encoding="utf-8", errors="replace")
        import shutil

        if shutil.which(spec.argv[0]) is None:  # the guard would only say so in the log
            self._log.close()
            raise RobotError(f"{spec.name}: cannot start {spec.argv[0]}: no such program")
        try:
            self.popen = subprocess.Popen(
                guarded(spec.argv), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL, text=True, errors="replace",
                env={**os.environ, **spec.env}, start_new_session=True)
        except OSError as exc:
            self._log.close()
            raise RobotError(f"{spec.name}: cannot start {spec.argv[0]}: {exc}") from None
        if spec.ready_text is None:
            self._ready.set()
        self._reader = threading.Thread(target=self._read, name=f"robot-{spec.name}",
                                        daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        text = self.spec.ready_text
        for line in self.popen.stdout:
            self._log.write(line)
            self._log.flush()
            if line.strip():
                self.last_line = line.strip()
            if text is not None and text in line:
                self._ready.set()
        self._ended.set()

    @property
    def ready(self) -> bool:
        return self._ready.is_set()

    def poll(self) -> int | None:
        return self.popen.poll()

    def wait_ready(self, should_stop: Callable[[], bool] = lambda: False) -> None:
        """Block until the ready text shows; RobotError when the child ends first or stays
        silent past its start timeout (or ``should_stop`` says so: a Ctrl-C)."""
        deadline = time.monotonic() + self.spec.start_timeout
        while not self._ready.wait(0.1):
            if should_stop():
                raise KeyboardInterrupt
            if self._ended.is_set() or self.popen.poll() is not None:
                self._ended.wait(1.0)
                raise RobotError(f"{self.spec.name} ended while starting (exit code "
                                 f"{self.popen.wait()}): {self.last_line or 'no output'}; "
                                 f"see {self.log_path}")
            if time.monotonic() > deadline:
                raise RobotError(f"{self.spec.name} not ready after {self.spec.start_timeout:g}"
                                 f" s; see {self.log_path}")

    def tail(self, n: int = 3) -> list[str]:
        """The last ``n`` non-empty lines of the child's log (a crash's own last words)."""
        try:
            with open(self.log_path, "rb") as f:
                f.seek(0, os.SEEK_END)
                f.seek(max(0, f.tell() - 16384))
                text = f.read().decode("utf-8", "replace")
        except OSError:
            return []
        return [line.strip() for line in text.splitlines() if line.strip()][-n:]

    def stop(self, grace: float = STOP_GRACE) -> int:
        """SIGINT (a Ctrl-C), then SIGKILL after ``grace`` s; the exit code."""
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.popen.pid, signal.SIGINT)
            try:
                self.popen.wait(grace)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait()
        self._reader.join(2.0)
        self._log.close()
        if self.final_lines is None:
            self.final_lines = self.tail(3)
        return self.popen.returncode


class Supervisor:
    """Starts ``specs`` in order; :meth:`watch` until one ends or :meth:`request_stop`."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.children: list[Child] = []
        self._stop = threading.Event()

    def request_stop(self) -> None:
        """Safe from a signal handler: the start or watch loop ends at its next poll."""
        self._stop.set()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def start(self, specs: Sequence[ChildSpec],
              on_ready: Callable[[Child], None] = lambda child: None) -> None:
        for spec in specs:
            child = Child(spec, self.log_dir / f"{spec.name}.log")
            self.children.append(child)
            child.wait_ready(lambda: self._stop.is_set())
            on_ready(child)

    def watch(self, every: float = 0.5, on_tick: Callable[[], None] = lambda: None,
              on_lost: Callable[[Child], None] = lambda child: None,
              on_respawn: Callable[[Child, Child], None] = lambda old, new: None,
              on_down: Callable[[Child], None] = lambda child: None) -> Child | None:
        """Until an essential child ends (returned) or a stop is requested (None); a child
        that is not essential ending is handed to ``on_lost`` once and the watch goes on; a
        child to respawn is started again (its log goes on) after :data:`RESPAWN_DELAY` and
        handed to ``on_respawn(old, new)`` (one that cannot start again ends the run). A child
        to respawn or an essential one that ended is handed to ``on_down`` first, while the
        others still run (to report it)."""
        lost: set[str] = set()
        while not self._stop.wait(every):
            for i, child in enumerate(self.children):
                if child.poll() is None:
                    continue
                if child.spec.respawn or child.spec.essential:
                    on_down(child)
                if child.spec.respawn:
                    if self._stop.wait(RESPAWN_DELAY):
                        return None
                    child.stop()  # its reader and log closed
                    try:
                        new = Child(child.spec, child.log_path, append=True)
                        new.respawns = child.respawns + 1
                        self.children[i] = new
                        new.wait_ready(lambda: self._stop.is_set())
                    except KeyboardInterrupt:
                        return None
                    except RobotError:
                        return self.children[i]
                    on_respawn(child, new)
                    continue
                if child.spec.essential:
                    return child
                if child.spec.name not in lost:
                    lost.add(child.spec.name)
                    on_lost(child)
            on_tick()
        return None

    def stop_all(self) -> dict[str, int]:
        """Stop every child, the last started first; their exit codes."""
        codes: dict[str, int] = {}
        for child in reversed(self.children):
            codes[child.spec.name] = child.stop()
        return codes
