"""benchmarks/cli_runs.py: the CLI commands timed as users run them (issue 22 item 25)."""

from __future__ import annotations

import subprocess

import pytest

from benchmarks import cli_runs


def test_factor_subtracts_the_startup() -> None:
    run = cli_runs.CliRun(simulated=600.0, total_cpu=4.0, startup_cpu=1.0)
    assert run.factor == pytest.approx(200.0)
    assert run.factor_with_startup == pytest.approx(150.0)


def test_emulate_runs_the_command_in_a_child_and_counts_its_cpu() -> None:
    run = cli_runs.emulate(1.0, ("-i", "virtual"))
    assert run.simulated == 1.0
    assert run.startup_cpu > 0.0
    assert run.total_cpu > 0.0
    assert run.factor > 0.0


def test_a_failing_command_raises() -> None:
    with pytest.raises(subprocess.CalledProcessError):
        cli_runs.child_cpu(["emulate", "--simulated"])  # --simulated needs --duration
