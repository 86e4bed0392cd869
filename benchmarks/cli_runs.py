"""The commands users run, run as they run them: ``python -m lowerbase ...`` in a child process,
timed by the child's CPU time (user + sys, ``resource.getrusage(RUSAGE_CHILDREN)``), with the
start-up (imports, the cached numba kernels, opening the bus) measured apart by the same command
with a tiny duration and reported separately."""

from __future__ import annotations

import os
import re
import resource
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

#: the simulated seconds of the start-up run (one period is 5 ms)
STARTUP_SECONDS = 0.01


@dataclass(frozen=True)
class CliRun:
    """One command's CPU seconds for ``simulated`` seconds and for its start-up alone."""

    simulated: float
    total_cpu: float
    startup_cpu: float

    @property
    def factor(self) -> float:
        """Simulated seconds per CPU second, start-up subtracted."""
        return self.simulated / max(self.total_cpu - self.startup_cpu, 1e-9)

    @property
    def factor_with_startup(self) -> float:
        """Simulated seconds per CPU second, start-up included (what one run costs)."""
        return self.simulated / max(self.total_cpu, 1e-9)


def child_cpu(argv: Sequence[str], timeout: float = 1800.0, check: bool = True) -> float:
    """CPU seconds (user + sys) that ``python -m lowerbase ARGV`` took; raises on a failure
    (with ``check``: a scenario whose expectations fail exits non-zero too)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-m", "lowerbase", *argv], check=check, timeout=timeout,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env={**os.environ, "PYTHONUNBUFFERED": "1"})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def emulate(seconds: float, bus: Sequence[str] = ()) -> CliRun:
    """``lowerbase emulate [BUS] --simulated --duration SECONDS`` (no bus option:
    udp_multicast, as a user runs it; ``("-i", "virtual")``: python-can's virtual bus)."""
    def cmd(duration: float) -> list[str]:
        return ["emulate", *bus, "--simulated", "--duration", f"{duration:g}"]

    startup = child_cpu(cmd(STARTUP_SECONDS))
    return CliRun(seconds, child_cpu(cmd(seconds)), startup)


def with_duration(toml: str, seconds: float) -> str:
    """A scenario file's text with its ``[scenario]`` duration set to ``seconds``."""
    head, sep, rest = toml.partition("[scenario]")
    if not sep:
        raise ValueError("no [scenario] table")
    rest, n = re.subn(r"(?m)^duration\s*=\s*[0-9.eE+-]+", f"duration = {seconds!r}", rest,
                      count=1)
    if not n:
        raise ValueError("no duration in [scenario]")
    return head + sep + rest


def scenario(path: Path, seconds: float, extra: Sequence[str] = ()) -> CliRun:
    """``lowerbase scenario run FILE [EXTRA]`` on a copy of the scenario ``path`` lengthened to
    ``seconds`` (its timeline unchanged, then idle), report to a temporary directory; the
    start-up is the same copy with a duration of one period (expectations not checked)."""
    text = path.read_text()
    with tempfile.TemporaryDirectory(prefix="lowerbase-cli-bench-") as tmp:
        def cpu(duration: float, check: bool) -> float:
            file = Path(tmp) / f"{path.stem}-{duration:g}.toml"
            file.write_text(with_duration(text, duration))
            return child_cpu(["scenario", "run", str(file), "--out",
                              str(Path(tmp) / f"out-{duration:g}"), *extra], check=check)

        startup = cpu(0.005, check=False)
        return CliRun(seconds, cpu(seconds, check=False), startup)
