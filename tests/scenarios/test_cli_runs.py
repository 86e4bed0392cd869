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


def test_with_duration_sets_the_scenario_duration_only() -> None:
    toml = ('[scenario]\nname = "x"\nduration = 21.0\n\n[[timeline]]\nat = 1.0\n'
            'duration = 3.0\n')
    out = cli_runs.with_duration(toml, 600.0)
    assert 'duration = 600.0\n\n[[timeline]]' in out
    assert out.endswith("duration = 3.0\n")
    with pytest.raises(ValueError):
        cli_runs.with_duration("[[timeline]]\nduration = 1.0\n", 5.0)
