"""blocked_delay (and the other TaskConfig values) from a scenario's [tasks] table and from
`lowerbase tasks` options: the value reaches the machine's config; a bad one is one typed line
that names the key or the option."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from lowerbase.cli import main
from lowerbase.errors import ConfigError
from lowerbase.scenarios.tasks import load_tasks_scenario
from lowerbase.tasks import node
from lowerbase.tasks.plan import TaskConfig

HEAD = "[scenario]\nduration = 10.0\n[world]\nmap = 'empty_room'\n[tasks]\n"


def test_a_scenario_sets_blocked_delay(tmp_path: Path) -> None:
    p = tmp_path / "s.toml"
    p.write_text(HEAD + "blocked_delay = 2.5\n")
    assert load_tasks_scenario(p).config.blocked_delay == 2.5
    p.write_text(HEAD + "blocked_delay = 0\n")  # an integer 0: warn at once
    assert load_tasks_scenario(p).config.blocked_delay == 0.0
    p.write_text(HEAD)
    assert load_tasks_scenario(p).config.blocked_delay == TaskConfig().blocked_delay == 0.5


@pytest.mark.parametrize("value, text", [
    ("-0.5", "[tasks]: task config blocked_delay must be a number >= 0, got -0.5"),
    ("nan", "[tasks]: task config blocked_delay must be a number >= 0, got nan"),
    ("'long'", "[tasks]: blocked_delay must be a number, not 'long'"),
    ("true", "[tasks]: blocked_delay must be a number, not True"),
])
def test_a_bad_blocked_delay_in_a_scenario_is_one_line(tmp_path: Path, value: str,
                                                       text: str) -> None:
    p = tmp_path / "bad.toml"
    p.write_text(HEAD + f"blocked_delay = {value}\n")
    with pytest.raises(ConfigError) as err:
        load_tasks_scenario(p)
    assert str(err.value) == text


@pytest.fixture
def setups(monkeypatch: pytest.MonkeyPatch) -> list[node.TasksSetup]:
    """`lowerbase tasks` up to the node: the setups it would run (no ROS needed)."""
    got: list[node.TasksSetup] = []

    def run(setup: node.TasksSetup, ros_args: Any, where: str) -> int:
        got.append(setup)
        return 0

    monkeypatch.setattr(node, "import_ros", lambda: None)
    monkeypatch.setattr(node, "run", run)
    return got


def test_the_tasks_command_sets_blocked_delay(setups: list[node.TasksSetup]) -> None:
    assert main(["tasks", "--map", "empty_room", "--blocked-delay", "1.5"]) == 0
    assert main(["tasks", "--map", "empty_room"]) == 0
    assert [s.config.blocked_delay for s in setups] == [1.5, 0.5]
    assert setups[0].config == TaskConfig(blocked_delay=1.5)  # nothing else changed


@pytest.mark.parametrize("args, line", [
    (["--blocked-delay", "-1"], "--blocked-delay must be a number >= 0, got -1.0"),
    (["--blocked-delay", "inf"], "--blocked-delay must be a number >= 0, got inf"),
    (["--unload-time", "0"], "--unload-time must be a number > 0, got 0.0"),
    (["--full-soc", "120"], "--full-soc must be within (0, 100], got 120.0"),
])
def test_a_bad_option_is_one_line_naming_it(setups: list[node.TasksSetup],
                                            capsys: pytest.CaptureFixture[str],
                                            args: list[str], line: str) -> None:
    assert main(["tasks", "--map", "empty_room", *args]) == 1
    assert capsys.readouterr().err.strip().splitlines() == [f"lowerbase tasks: error: {line}"]
    assert setups == []
