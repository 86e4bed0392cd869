"""Shared fixtures: free loopback ports, isolated multicast buses, subprocess helpers."""

from __future__ import annotations

import contextlib
import importlib
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

from lowerbase.transport import free_loopback_port

# Property and fuzz tests draw the same examples on every run (deterministic tests); set
# HYPOTHESIS_PROFILE=explore locally to search with fresh random examples.
settings.register_profile("deterministic", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))

ROOT = Path(__file__).resolve().parents[1]
# The process tests press Ctrl-C (SIGINT) on the processes they start. A shell that starts the
# suite in the background without job control (`make test &` in a script, some CI runners)
# makes it ignore SIGINT, and an ignored signal stays ignored in every child: each Ctrl-C would
# be lost. With a handler here, the children start with the default again (exec resets it).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
# udp_multicast buses join their group on loopback only (no IGMP report on the host's network;
# children inherit it); tests/transport/test_multicast_netns.py tests the default join in a
# network namespace of its own
os.environ["LOWERBASE_MULTICAST_JOIN"] = "loopback"
#: a multicast group of the tests' own; each test also gets its own port
TEST_GROUP = "239.74.163.99"
#: ``lowerbase conformance`` against an emulator process on the test host: the suite's limits
#: add the host's timestamp allowance (--jitter, 0.05 s for a bench host) and allow a mean cycle
#: 10 % off. A 2-core machine running the test suite schedules the emulator and the suite up to
#: ~0.1 s late and stretches a 10 ms cycle by ~12 %, so the process tests allow 0.15 s and 30 %;
#: the defects they must catch are 0.3 s late or a cycle twice as long.
LOADED_HOST = ("--jitter", "0.15", "--cycle-tolerance", "0.3")


def free_udp_port() -> int:
    return free_loopback_port(socket.SOCK_DGRAM)


def free_tcp_port() -> int:
    return free_loopback_port(socket.SOCK_STREAM)


@pytest.fixture
def udp_bus_config() -> dict[str, Any]:
    """A udp_multicast configuration no other test (or parallel run) shares."""
    return {"interface": "udp_multicast", "channel": TEST_GROUP, "port": free_udp_port(),
            "hop_limit": 0}


def bus_cli_args(config: dict[str, Any]) -> list[str]:
    """The same configuration as python-can command-line flags."""
    extra = [f"{k}={v}" for k, v in config.items() if k not in ("interface", "channel")]
    args = ["-i", config["interface"], "-c", str(config["channel"])]
    return args + (["--bus-kwargs", *extra] if extra else [])


class Proc:
    """A lowerbase subprocess whose stdout is collected line by line by a reader thread."""

    def __init__(self, args: list[str], env: dict[str, str] | None = None) -> None:
        self.popen = subprocess.Popen(
            [sys.executable, "-m", "lowerbase", *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
            env={**os.environ, **(env or {})},
        )
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        try:
            for line in self.popen.stdout:
                self._queue.put(line)
        except ValueError:  # stop()/wait()'s communicate() closed stdout under this thread
            pass
        self._queue.put(None)

    def wait_for(self, text: str, timeout: float = 20.0) -> str:
        """The first stdout line (from now on) containing ``text``; AssertionError after
        ``timeout`` [s] or when the process ends first."""
        deadline = time.monotonic() + timeout
        while (remaining := deadline - time.monotonic()) > 0:
            try:
                line = self._queue.get(timeout=remaining)
            except queue.Empty:
                break
            if line is None:
                break
            self.lines.append(line)
            if text in line:
                return line
        done = self.popen.poll() is not None
        err = self.popen.stderr.read() if done and self.popen.stderr else ""
        raise AssertionError(f"{text!r} not printed; stdout={self.lines!r} stderr={err!r}")

    def wait(self, timeout: float = 20.0) -> tuple[int, str]:
        """Wait for the process to end by itself; (exit code, stderr)."""
        try:
            _, err = self.popen.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            _, err = self.popen.communicate()
            raise AssertionError(f"still running after {timeout} s; stderr={err!r}") from None
        return self.popen.returncode, err

    def stop(self, timeout: float = 10.0) -> tuple[int, str]:
        if self.popen.poll() is None:
            self.popen.send_signal(2)  # Ctrl-C
        try:
            _, err = self.popen.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            _, err = self.popen.communicate()
        return self.popen.returncode, err


@pytest.fixture
def lowerbase_proc() -> Iterator[Any]:
    procs: list[Proc] = []

    def start(*args: str, env: dict[str, str] | None = None) -> Proc:
        p = Proc(list(args), env)
        procs.append(p)
        return p

    yield start
    for p in procs:
        p.stop()


@contextlib.contextmanager
def first_on_path(out: Path, generated: Callable[[str], bool]) -> Iterator[Path]:
    """Put freshly generated message packages in ``out`` first on ``sys.path``; modules for
    which ``generated(name)`` holds that were already imported (a venv .pth to build/ros) are
    hidden meanwhile and restored after, so tests check what this checkout generates."""
    saved = {k: v for k, v in sys.modules.items() if generated(k)}
    for k in saved:
        del sys.modules[k]
    sys.path.insert(0, str(out))
    importlib.invalidate_caches()
    try:
        yield out
    finally:
        sys.path.remove(str(out))
        for k in [k for k in sys.modules if generated(k)]:
            del sys.modules[k]
        sys.modules.update(saved)


@contextlib.contextmanager
def every_msggen_package(out: Path, hidden: Iterable[str]) -> Iterator[Path]:
    """Every msggen package generated into ``out``, first on ``sys.path`` (:func:`first_on_path`,
    the already imported modules of the ``hidden`` packages hidden meanwhile)."""
    from lowerbase.driver import msggen

    names = tuple(hidden)
    for package in msggen.PACKAGES:
        msggen.generate(out, package=package)
    with first_on_path(out, lambda m: any(m == p or m.startswith(p + ".") for p in names)) as path:
        yield path
