"""Task scenarios (lowerbase/scenarios/tasks.py, tasks_run.py): the library passes on the
whole emulated robot, a wrong expectation fails, move_base goals drive the navigator, bad files
are one-line ConfigErrors. The demo (scenarios/tasks/demo.toml) runs in
tests/reports/test_report_tasks.py, once, with its report."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from lowerbase.errors import ConfigError
from lowerbase.scenarios.tasks import library_tasks, load_tasks_scenario
from lowerbase.scenarios.tasks_run import report, run_tasks_scenario

HEAD = """
[scenario]
duration = {duration}
[world]
map = "empty_room"
[tasks]
unload_time = 2.0
"""


def test_the_library_has_one_per_task_type_a_fault_and_a_shift() -> None:
    assert set(library_tasks()) == {"transport", "picking", "parking", "charging",
                                    "fault_during_task", "shift", "demo"}


@pytest.mark.parametrize("name", sorted(set(library_tasks()) - {"demo"}))
def test_every_task_scenario_passes(name: str) -> None:
    result = run_tasks_scenario(load_tasks_scenario(library_tasks()[name]))
    assert result.passed, report(result)
    assert result.responses and result.responses[0][2]  # its first request was accepted


def test_a_wrong_expectation_fails(tmp_path: Path) -> None:
    p = tmp_path / "s.toml"
    p.write_text(HEAD.format(duration=40.0) + """
[[timeline]]
at = 1.0
action = "exec_task"
task_id = 1
task_type = 4
direction = 2
mark_no = "R1"
[[expect]]
kind = "task_duration"
task_id = 1
within = [0.0, 3.0]
[[expect]]
kind = "robot_status"
task_id = 1
sequence = ["executing", "failed"]
[[expect]]
kind = "robot_status"
task_id = 2
sequence = ["executing"]
""")
    result = run_tasks_scenario(load_tasks_scenario(p))
    assert [ok for _, ok, _ in result.outcomes] == [False, False, False], report(result)
    assert "took" in result.outcomes[0][2] and "never published" in result.outcomes[2][2]


def test_move_base_goals_drive_the_navigator(tmp_path: Path) -> None:
    p = tmp_path / "s.toml"
    p.write_text(HEAD.format(duration=30.0) + """
[[timeline]]
at = 1.0
action = "move_base"
target = [7.0, 5.0, 0.0]
""")
    result = run_tasks_scenario(load_tasks_scenario(p))
    x, y, _ = result.sim.world.true_pose()
    assert math.hypot(x - 7.0, y - 5.0) < 0.15


@pytest.mark.parametrize("body, text", [
    ("", "needs [world] and [tasks]"),
    ("[world]\nmap = 'empty_room'\n[tasks]\nspeed = 1\n", "unknown key 'speed'"),
    ("[world]\nmap = 'empty_room'\n[tasks]\n[[timeline]]\nat = 1.0\naction = 'fly'\n",
     "action must be"),
    ("[world]\nmap = 'empty_room'\n[tasks]\n[[timeline]]\nat = 1.0\nfault = 'melt'\n",
     "melt"),
    ("[world]\nmap = 'empty_room'\n[tasks]\n[[timeline]]\nat = 1.0\naction = 'move_base'\n",
     "move_base needs"),
    ("[world]\nmap = 'empty_room'\n[tasks]\n[[expect]]\nkind = 'robot_status'\ntask_id = 1\n"
     "sequence = ['flying']\n", "'flying' is not a task_state"),
    ("[world]\nmap = 'empty_room'\n[tasks]\n[[timeline]]\nat = 1.0\naction = 'control'\n"
     "command = 'Explode'\n", "command must be one of"),
    ("[world]\nmap = 'empty_room'\n[tasks]\nload_time = 'long'\n", "load_time must be a number"),
    ("[world]\nmap = 'empty_room'\n[tasks]\nfull_soc = 0\n", "full_soc must be within"),
    ("[world]\nmap = 'empty_room'\n[tasks]\nauto_charge = 1\n", "auto_charge must be true"),
])
def test_bad_files_are_one_line_errors(tmp_path: Path, body: str, text: str) -> None:
    p = tmp_path / "bad.toml"
    p.write_text("[scenario]\nduration = 10.0\n" + body)
    with pytest.raises(ConfigError) as err:
        load_tasks_scenario(p)
    assert text in str(err.value) and "\n" not in str(err.value)


def test_a_run_is_deterministic() -> None:
    sc = load_tasks_scenario(library_tasks()["transport"])
    a, b = run_tasks_scenario(sc), run_tasks_scenario(sc)
    assert [(t, s) for t, s in a.history] == [(t, s) for t, s in b.history]
    np.testing.assert_array_equal(np.array(a.samples), np.array(b.samples))  # NaN == NaN
    assert a.plans == b.plans and len(a.samples) > 200
