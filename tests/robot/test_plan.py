"""What ``lowerbase robot`` starts (lowerbase.robot.plan.robot_plan) for its options, and its
one-line errors for bad ones: no ROS needed."""

from __future__ import annotations

import subprocess
import sys

from lowerbase.robot.plan import RobotOptions, robot_plan
from tests.conftest import ROOT


def argv_of(opts: RobotOptions) -> dict[str, list[str]]:
    return {s.name: list(s.argv) for s in robot_plan(opts)}


def test_soc_and_ground_truth_reach_the_emulator_and_the_world() -> None:
    plain = argv_of(RobotOptions(map="empty_room", bus_port=1, truth_port=2))
    assert "--soc" not in plain["emulate"] and "--ground-truth" not in plain["world"]
    both = argv_of(RobotOptions(map="empty_room", bus_port=1, truth_port=2, soc=30.0,
                                ground_truth=True))
    emulate = both["emulate"]
    assert emulate[emulate.index("--soc") + 1] == "30"
    assert "--ground-truth" in both["world"]
    assert [n for n in both] == ["world", "emulate", "driver", "navigation", "tasks"]


def test_a_bad_soc_is_refused_before_anything_starts() -> None:
    for text in ("101", "-1", "nan", "full"):
        out = subprocess.run([sys.executable, "-m", "lowerbase", "robot", "--soc", text],
                             capture_output=True, text=True, cwd=ROOT, timeout=60)
        assert out.returncode != 0
        assert "--soc" in out.stderr and "Traceback" not in out.stderr, out.stderr
